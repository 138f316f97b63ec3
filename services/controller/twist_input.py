"""ROS 2 Twists on `/<robot>/cmd_vel` as operator input: the same policy as a console's commands. Pure.

A Twist (geometry_msgs/msg/Twist, CDR) with its rmw_zenoh attachment (protocol/rmw_zenoh.py) becomes the
`OperatorCommand` the console's keyboard would send for the same handle (services/console/operator.py,
`KeyboardCommandSource`), and goes through `OperatorInputPolicy.admit` like every command:

* **Sender** — the publisher's GID from the attachment: operator id ``ros2-<GID in hex>``, session id the
  GID in hex. Each ROS 2 publisher is a sender of its own (its own lease, sequence and rate budget).
* **Order and age** — the attachment's sequence number is the command's seq, its source timestamp
  (ns since the epoch, the sender's wall clock) the send time: the replay guard drops duplicates,
  out-of-order and stale Twists (replay_guard.py), the rate limit applies per sender (admission.py).
* **Lease** (lease.py) — only the holder's Twists drive (`not_holder`, `no_lease`). Implicit mode: a
  Twist while nobody holds control takes it, as a console command does. Explicit mode: a Twist cannot
  take control (it has no control request and no lease query is made for it), so a ROS 2 sender
  never drives a controller in explicit mode (`no_lease`).
* **Handle** — the Twist is a joystick deflection in the robot's base frame (REP 105: linear.x
  forward, linear.y left, angular.z counter-clockwise): (linear.x, linear.y) / `max_linear` (its norm
  at most 1, the direction kept) rotated into the world by the yaw ψ, and angular.z / `max_angular`
  (within ±1). It is the joystick of (44): u_h = k_p ∘ deflection, a force — not a velocity set-point;
  the robot runs as fast as that force against its friction makes it. The wish is the keyboard's: the
  pose plus `reach` ∘ deflection, at rest. The deadman counts as held (a Twist has none: a zero Twist
  is a centred handle that still drives), no estop (a Twist has none). linear.z, angular.x and
  angular.y are ignored (a planar robot), once checked finite and bounded.
* **Staleness** — the same operator timeout: 0.3 s without an accepted Twist → hands-off. A ROS 2
  sender keeps driving only while it publishes more often than that.
* **Identity** — with an operators file (`policy.verify` set), a Twist has no Ed25519 signature: every
  one is refused (`ros2_unauthenticated`); ROS 2 senders are then authenticated only at the transport
  (a router's credentials and ACL), if at all, and never drive a signed controller.
* **Bad input** — an attachment that is not rmw_zenoh's (`ros2_bad_attachment`), a payload that is not
  a Twist's CDR (`ros2_bad_cdr`), a component that is not finite (`ros2_non_finite`) or beyond 100 m/s
  or rad/s (`ros2_out_of_range`): refused and counted, never reaching the actuator. From the lease
  holder, such a Twist also makes it hands-off at once (as a console's malformed command does).

Every refusal is counted twice: in the policy's `rejections` (the controller's `rejections` and
`link.rejected_messages`) and in this input's `refused` (the `ros2` part of its summary).
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

from sharedctl.protocol.errors import BadAttachment, BadCdr, NonFiniteValue, OutOfRange, ProtocolError
from sharedctl.protocol.messages import ControlRequest, OperatorCommand
from sharedctl.protocol.rmw_zenoh import Attachment
from sharedctl.protocol.ros2_messages import Twist

DEFAULT_MAX_LINEAR = 0.5      # m/s of a Twist at full deflection
DEFAULT_MAX_ANGULAR = 1.0     # rad/s of a Twist at full deflection
DEFAULT_REACH = (0.5, 0.5, 0.5)   # m, m, rad: the wish's offset at full deflection (the console's keyboard)

_VALUE_REASONS = ((BadCdr, "ros2_bad_cdr"), (NonFiniteValue, "ros2_non_finite"), (OutOfRange, "ros2_out_of_range"))


@dataclass(frozen=True)
class TwistScale:
    """What a full deflection is: `max_linear` m/s, `max_angular` rad/s; `reach`: the wish's offset then."""

    max_linear: float = DEFAULT_MAX_LINEAR
    max_angular: float = DEFAULT_MAX_ANGULAR
    reach: tuple[float, float, float] = DEFAULT_REACH

    def __post_init__(self) -> None:
        if not (0 < self.max_linear < math.inf and 0 < self.max_angular < math.inf):
            raise ValueError("a Twist's full scale (max linear, max angular) must be positive and finite")


def operator_id(gid: bytes) -> str:
    """The operator id of a ROS 2 publisher: ``ros2-`` and its GID in hex."""
    return f"ros2-{gid.hex()}"


def deflection(twist: Twist, yaw: float, scale: TwistScale) -> tuple[float, float, float]:
    """The Twist as a world-frame joystick deflection in [−1, 1] (module doc, "Handle")."""
    bx, by = twist.linear[0] / scale.max_linear, twist.linear[1] / scale.max_linear
    norm = math.hypot(bx, by)
    if norm > 1.0:
        bx, by = bx / norm, by / norm
    c, s = math.cos(yaw), math.sin(yaw)
    clip = lambda v: min(max(v, -1.0), 1.0)  # noqa: E731 — a rotation of a unit vector may round past 1
    return clip(c * bx - s * by), clip(s * bx + c * by), clip(twist.angular[2] / scale.max_angular)


def twist_command(twist: Twist, attachment: Attachment, pose, scale: TwistScale) -> OperatorCommand:
    """The OperatorCommand a console's keyboard would send for this Twist at `pose` (x, y, ψ)."""
    d = deflection(twist, float(pose[2]), scale)
    sender = attachment.gid.hex()
    zero = (0.0, 0.0, 0.0)
    return OperatorCommand(
        operator_id=operator_id(attachment.gid), session_id=sender, seq=attachment.sequence_number,
        send_time=attachment.source_timestamp_ns * 1e-9, joystick=d,
        q_d=tuple(float(p) + r * k for p, r, k in zip(pose, scale.reach, d)), qd_d=zero, qdd_d=zero,
        deadman=True, estop=False, control_request=ControlRequest.NONE)


@dataclass
class TwistInput:
    """Twist payloads with their attachments → `policy` (an `OperatorInputPolicy`); `codec.twist(payload)`
    decodes (protocol/ros2_messages.py `Ros2Codec`). `offer` has the signature `CommandIntake` calls."""

    policy: object
    codec: object
    scale: TwistScale = field(default_factory=TwistScale)
    received: int = 0
    accepted: int = 0
    refused: Counter = field(default_factory=Counter)

    @property
    def rejections(self) -> Counter:
        """The policy's (where `CommandIntake` counts a full queue)."""
        return self.policy.rejections

    def offer(self, payload: bytes, now: float, wall_now: float | None = None,
              attachment: bytes | None = None) -> bool:
        """Judge one Twist received at `now` (s, monotonic; `wall_now` wall clock). True if it drives."""
        self.received += 1
        reason = self._judge(payload, now, wall_now, attachment)
        if reason is None:
            self.accepted += 1
            return True
        self.refused[reason] += 1
        return False

    def _judge(self, payload: bytes, now: float, wall_now: float | None, attachment: bytes | None) -> str | None:
        policy = self.policy
        if policy.verify is not None:
            policy.rejections["ros2_unauthenticated"] += 1     # no signature: touches no session's state
            return "ros2_unauthenticated"
        try:
            meta = Attachment.decode(attachment)
        except BadAttachment:
            policy.rejections["ros2_bad_attachment"] += 1
            return "ros2_bad_attachment"
        try:
            twist = self.codec.twist(payload)
        except ProtocolError as exc:
            reason = next((r for kind, r in _VALUE_REASONS if isinstance(exc, kind)), "ros2_bad_cdr")
            policy.rejections[reason] += 1
            if policy.lease.holds(operator_id(meta.gid), meta.gid.hex(), now):
                policy.last_rejected = True          # the holder sent garbage: hands-off at once
            return reason
        try:
            command = twist_command(twist, meta, policy.pose, self.scale)
        except ProtocolError:                        # a negative sequence number, a timestamp before 1970
            policy.rejections["ros2_bad_attachment"] += 1
            return "ros2_bad_attachment"
        return policy.admit(command, now, wall_now)
