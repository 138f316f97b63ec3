"""The operator's link, in process: command rate, delay lines, Bernoulli loss, hold-last-value and staleness.

What the distributed system does between the console and the controller, without a network, so
every strategy of the comparison sees the same operator input:

* the operator samples at `rate` Hz (the console's 50 Hz), looking at the robot state as it was
  `downlink_delay` seconds ago (telemetry latency), and deflects the handle by the human model
  (44); the wire clips the deflection to [−1, 1] (services/console/operator.py);
* each command is lost with probability `loss` (Bernoulli, from a seeded generator), otherwise
  it arrives `uplink_delay` seconds after it was sent;
* the controller holds the newest arrived command (u_h = k_p ∘ d (44), v_h = ½ Σ k_p d² (45), the
  wish as sent); silent for more than `timeout` (0.3 s, services/controller/operator_input.py):
  hands-off — u_h = 0, v_h = 0, the wish held at the last q_d with zero rates. Before any
  command: hands-off at the current pose.

Pure and deterministic: time is the caller's, randomness is `numpy.random.default_rng(seed)`.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..human import HumanModel, intent
from ..shared_controller import OperatorInput
from ..transform import Desired

HANDS_OFF_TIMEOUT = 0.3   # s, as the controller daemon's operator policy


@dataclass(frozen=True)
class LinkConditions:
    """One network condition: delays (s), loss probability, command rate (Hz), seed."""

    name: str = "ideal"
    uplink_delay: float = 0.0
    downlink_delay: float = 0.0
    loss: float = 0.0
    rate: float = 50.0
    seed: int = 0
    timeout: float = HANDS_OFF_TIMEOUT

    def __post_init__(self):
        if self.uplink_delay < 0 or self.downlink_delay < 0 or not 0.0 <= self.loss < 1.0 or self.rate <= 0:
            raise ValueError("delays must be >= 0, loss in [0, 1), rate > 0")


IDEAL = LinkConditions()
#: the impaired condition of the comparison: 100 ms each way, one command in five lost
IMPAIRED = LinkConditions("latency+loss", uplink_delay=0.1, downlink_delay=0.1, loss=0.2, seed=7)


@dataclass(frozen=True)
class _Sent:
    arrival: float
    deflection: np.ndarray
    desired: Desired


@dataclass
class OperatorLink:
    """The operator model behind the link; call `input_at(t, q, v)` once per control period, in time order."""

    human: HumanModel
    conditions: LinkConditions = IDEAL
    sent: int = 0
    lost: int = 0
    _rng: np.random.Generator = field(init=False, repr=False)
    _in_flight: deque = field(default_factory=deque, repr=False)
    _history: deque = field(default_factory=deque, repr=False)   # (t, q, v) for the delayed telemetry
    _next_send: float = 0.0
    _current: _Sent | None = None
    _received_at: float = -math.inf

    def __post_init__(self):
        self._rng = np.random.default_rng(self.conditions.seed)

    def input_at(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[OperatorInput, bool]:
        """The controller's operator input for the period starting at t, and whether it is hands-off."""
        c = self.conditions
        self._history.append((t, np.array(q, float), np.array(v, float)))
        while len(self._history) > 1 and self._history[1][0] <= t - c.downlink_delay + 1e-12:
            self._history.popleft()
        while t + 1e-12 >= self._next_send:
            self._send(self._next_send)
            self._next_send += 1.0 / c.rate
        while self._in_flight and self._in_flight[0].arrival <= t + 1e-12:
            self._current = self._in_flight.popleft()
            self._received_at = self._current.arrival
        n = len(self.human.kp)
        zero = np.zeros(n)
        if self._current is None:
            return OperatorInput(Desired(np.array(q, float), zero, zero.copy()), zero.copy(), 0.0), True
        if t - self._received_at > c.timeout:
            return OperatorInput(Desired(self._current.desired.q, zero, zero.copy()), zero.copy(), 0.0), True
        d = self._current.deflection
        kp = np.asarray(self.human.kp, float)
        return OperatorInput(self._current.desired, kp * d, intent(kp, d)), False

    def _send(self, t_send: float) -> None:
        _, q_seen, v_seen = self._history[0]          # the newest state at least downlink_delay old
        wish = self.human.desired(t_send)
        deflection = np.clip(self.human.command_from(t_send, wish, q_seen, v_seen).deflection, -1.0, 1.0)
        deflection = np.where(np.isfinite(deflection), deflection, 0.0)
        self.sent += 1
        if self.conditions.loss and self._rng.random() < self.conditions.loss:
            self.lost += 1
            return
        self._in_flight.append(_Sent(t_send + self.conditions.uplink_delay, deflection, wish))
