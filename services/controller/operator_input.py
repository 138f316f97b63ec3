"""Operator commands from the wire → the shared controller's `OperatorInput`, with the staleness policy.

Pure: payload bytes and reception times in, `OperatorInput` out; the caller supplies the clock.

* The joystick spring (44): u_h = k_p ∘ d with d the normalised deflection in [−1, 1];
  the intent (45): v_h = ½ Σ_j k_p,j d_j² (`sharedctl.human.intent`).
* The wish: q_d, q̇_d, q̈_d as sent (`sharedctl.transform.Desired`).
* Ordering and age (`replay_guard.py`): per session, only a seq newer than the newest accepted
  one is taken (duplicates and older seqs are dropped and counted), and a command arriving more
  than 0.5 s later than the session's best delivery is `stale` (the clock offset between the
  hosts cancels; an absolute `max_skew` bound is optional). A new session id starts its own
  sequence (an operator restart).
* Authority (`lease.py`): only the lease holder's commands drive (`not_holder` / `no_lease`
  otherwise, counted); a command's control_request is an in-band take/release; in the default
  implicit mode a command while nobody holds the lease takes it. The holder's last accepted
  command is the current one; once the lease is released or expired it no longer drives
  (reason `no_lease`, hands-off).
* Identity (`verify`, set when the controller has an operators file: services/security/signing.py):
  a command counts only with a valid signature, by an operator trusted for this robot, over this
  robot's command key and the payload, and only if the `operator_id` it carries is the signer's
  (`identity_mismatch` otherwise). Everything after — order, rate, lease — keys on that verified
  id. A message that fails is counted by reason (`unsigned`, `bad_attachment`,
  `unknown_operator`, `not_permitted`, `bad_signature`, `identity_mismatch`) and touches no state
  of any session: it neither advances a sequence, spends a rate budget, nor makes the holder
  hands-off. Without `verify` the operator id is what the command says (a single-operator bench).
* Estop: an `estop` in any well-formed command — from any operator, holder or not, even one
  dropped as stale, duplicated or out of order — latches `estop_requested` (fail-safe: a replay
  can stop the robot, never move it). With `verify`, from any verified operator of this robot.
* Hands-off (u_h = 0, v_h = 0, wish held at the last q_d with zero rates) when the operator
  has been silent for more than `timeout` (0.3 s), the deadman is released, or the last
  payload was rejected (malformed or invalid: a `ProtocolError` from the decoder). Before
  any command the wish is the current pose, hands-off.
* `estop` in an accepted command latches `estop_requested` until `clear_estop()`.

Nothing raised by the decoder escapes `offer`: every rejection is counted by reason.
"""
from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np

from sharedctl.human import intent
from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.messages import ControlRequest, OperatorCommand
from sharedctl.protocol.msgpack_codec import decode_message
from sharedctl.protocol.wire_types import ROBOT_DIMS, Dims
from sharedctl.shared_controller import OperatorInput
from sharedctl.transform import Desired

from .admission import LEASE_BURST, LEASE_RATE, RateLimit, WishBounds
from .lease import OperatorLease
from .replay_guard import ReplayGuard

DEFAULT_TIMEOUT = 0.3   # s of operator silence before hands-off


@dataclass(frozen=True)
class OperatorStatus:
    """What the policy decided at one instant (for telemetry and events)."""

    hands_off: bool
    reason: str                  # "active", "no_command", "stale", "deadman", "rejected", "no_lease"
    staleness: float             # s since the last accepted command (inf before any)
    latency: float               # s, receive time − send time of the last accepted command (0 if unknown)
    loss_fraction: float         # seq gaps over the recent window of the current session
    operator_id: str | None      # sender of the current command
    estop_requested: bool


@dataclass
class OperatorInputPolicy:
    """Turns received `OperatorCommand`s into the `OperatorInput` of every control period."""

    kp: np.ndarray                           # joystick spring constant k_p per coordinate
    timeout: float = DEFAULT_TIMEOUT
    dims: Dims = ROBOT_DIMS
    loss_window: int = 200                   # seqs over which the loss fraction is estimated
    rejections: Counter = field(default_factory=Counter)
    accepted: int = 0
    current: OperatorCommand | None = None
    received_at: float = -math.inf
    latency: float = 0.0
    last_rejected: bool = False
    estop_requested: bool = False
    take_requests: int = 0                   # accepted commands asking control_request = take
    lease: OperatorLease = field(default_factory=OperatorLease)   # who may command (lease.py)
    guard: ReplayGuard = field(default_factory=ReplayGuard)       # order and age (replay_guard.py)
    limit: RateLimit = field(default_factory=RateLimit)           # commands per session (admission.py)
    lease_limit: RateLimit = field(default_factory=lambda: RateLimit(LEASE_RATE, LEASE_BURST))   # lease queries
    bounds: WishBounds = field(default_factory=WishBounds)        # the wish near the robot (admission.py)
    pose: object = None                                           # the robot's pose, as the loop last read it
    verify: object = None           # (payload, attachment) -> (signer, reason): operator identity, or None (signing.py)
    _recent: deque = field(default_factory=deque)        # seqs of the current session
    _input_of: tuple | None = None                        # (command, hands_off) that `_input` was built from
    _input: OperatorInput | None = None

    def __post_init__(self) -> None:
        self.kp = np.asarray(self.kp, dtype=float)

    # ------------------------------------------------------------------ input
    def offer(self, payload: bytes, now: float, wall_now: float | None = None, attachment: bytes | None = None) -> bool:
        """Decode and judge one payload received at `now` (s, controller clock). True if accepted.

        `wall_now` (s, same clock as the sender's `send_time`) gives the latency; None: unknown.
        `attachment`: the sample's Zenoh attachment (the operator's signature, checked when `verify` is set).
        """
        signer = None
        if self.verify is not None:
            signer, reason = self.verify(payload, attachment)
            if reason is not None:
                self.rejections[reason] += 1     # not the holder's doing: its input stays as it was
                return False
        try:
            command = decode_message(bytes(payload), self.dims, expect=OperatorCommand)
        except ProtocolError as exc:
            self.rejections[type(exc).__name__] += 1
            self.last_rejected = True
            return False
        except Exception as exc:  # noqa: BLE001 — a bad payload never escapes a receive path
            self.rejections[f"unexpected_{type(exc).__name__}"] += 1
            self.last_rejected = True
            return False
        if signer is not None and command.operator_id != signer:
            self.rejections["identity_mismatch"] += 1
            return False
        return self.accept(command, now, wall_now)

    def accept(self, command: OperatorCommand, now: float, wall_now: float | None = None) -> bool:
        """Apply the estop, ordering, age and lease policy to a decoded command."""
        return self.admit(command, now, wall_now) is None

    def admit(self, command: OperatorCommand, now: float, wall_now: float | None = None) -> str | None:
        """`accept`, saying why not: None if the command was taken, else the reason it was refused (counted in
        `rejections`) or "released" (the holder let go: not a rejection)."""
        if command.estop:
            self.estop_requested = True          # honoured from anyone, before any other check
        # keyed by operator and session: another sender naming this session cannot advance its seq
        key = f"{command.operator_id}/{command.session_id}"
        reason = self.guard.admit(key, command.seq, command.send_time, now, wall_now)
        if reason is None and not self.limit.admit(key, now):
            reason = "rate_limited"
        if reason is None:
            reason = self.bounds.judge(command.q_d, command.qd_d, command.qdd_d,
                                       command.q_d if self.pose is None else self.pose)
        if reason is None:
            reason = self.lease.admit_command(command.operator_id, command.session_id, command.control_request, now)
            if reason is None:
                self.guard.pin(f"{command.operator_id}/{command.session_id}")   # the lease let it act
        if reason == "released":
            return reason                        # the holder let go: not a rejection
        if reason is not None:
            self.rejections[reason] += 1
            return reason
        if self.current is None or command.session_id != self.current.session_id:
            self._recent.clear()
        self._recent.append(command.seq)
        while len(self._recent) > self.loss_window:
            self._recent.popleft()
        self.current, self.received_at = command, now
        self.accepted += 1
        self.last_rejected = False
        if wall_now is not None:
            latency = wall_now - command.send_time
            self.latency = latency if 0.0 <= latency < 60.0 else 0.0
        if command.control_request is ControlRequest.TAKE:
            self.take_requests += 1
        return None

    def clear_estop(self) -> None:
        self.estop_requested = False

    # ----------------------------------------------------------------- output
    def status(self, now: float) -> OperatorStatus:
        staleness = now - self.received_at if self.current is not None else math.inf
        if self.current is None:
            reason = "no_command"
        elif self.last_rejected:
            reason = "rejected"
        elif not self.lease.holds(self.current.operator_id, self.current.session_id, now):
            reason = "no_lease"
        elif staleness > self.timeout:
            reason = "stale"
        elif not self.current.deadman:
            reason = "deadman"
        else:
            reason = "active"
        return OperatorStatus(
            hands_off=reason != "active", reason=reason, staleness=staleness, latency=self.latency,
            loss_fraction=self.loss_fraction(), operator_id=self.current.operator_id if self.current else None,
            estop_requested=self.estop_requested,
        )

    def operator_input(self, now: float, pose: np.ndarray) -> tuple[OperatorInput, OperatorStatus]:
        """The `OperatorInput` for the control period starting at `now`, robot at `pose`."""
        status = self.status(now)
        cmd = self.current
        if cmd is not None and self._input_of is not None and self._input_of[0] is cmd \
                and self._input_of[1] == status.hands_off:
            return self._input, status          # the same command, judged the same: the same input
        n = len(self.kp)
        zero = np.zeros(n)
        if cmd is None:
            return OperatorInput(Desired(np.asarray(pose, float).copy(), zero, zero.copy()), zero.copy(), 0.0), status
        q_d = np.asarray(cmd.q_d, dtype=float)
        if status.hands_off:
            built = OperatorInput(Desired(q_d, zero, zero.copy()), zero.copy(), 0.0)
        else:
            force = self.kp * np.asarray(cmd.joystick, dtype=float)                   # (44)
            built = OperatorInput(Desired(q_d, np.asarray(cmd.qd_d, dtype=float), np.asarray(cmd.qdd_d, dtype=float)),
                                  force, intent(self.kp.tolist(), cmd.joystick))       # (45)
        for array in (built.desired.q, built.desired.q_dot, built.desired.q_ddot, built.force):
            array.flags.writeable = False       # handed out again every period until the next command
        self._input_of, self._input = (cmd, status.hands_off), built
        return built, status

    def loss_fraction(self) -> float:
        """1 − received / span of seqs over the recent window of the current session."""
        if len(self._recent) < 2:
            return 0.0
        span = self._recent[-1] - self._recent[0] + 1
        return float(min(max(1.0 - len(self._recent) / span, 0.0), 1.0))

    @property
    def rejected(self) -> int:
        return sum(self.rejections.values())
