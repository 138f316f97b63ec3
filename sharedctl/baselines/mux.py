"""`mux`: twist_mux-style priority/timeout arbitration that hands control to a hold command at the border.

twist_mux (ROS) selects, among its input topics, the one of highest priority whose last message
is younger than that topic's timeout, and forwards it unchanged; nothing is blended. Here:

* **operator** — priority 10, timeout 0.3 s. Its staleness is the link's (operator_link.py): a
  silent operator is hands-off (u_h = 0), as in the controller daemon.
* **hold** — priority 100, timeout `hold_timeout` (0.5 s). A border monitor publishes one hold
  message every control period while the state is **near the border**, which uses the shared
  law's own bands (Definition 2 with b0, b1, b2, sets.py): the state is not SAFE — some row x_j
  of every polytope containing q is within b2 of its face and approaches it faster than the
  allowance f_b2(x_j) = 1/(x_j + b2) − 1/b2, or approaches at all within b0, or q is in no
  polytope. Standing still, or moving away from every face, is never "near the border": the
  shared law's standoff band (sets.py: a state at rest within b_s of a face is not safe, so that
  its machine keeps authority at its rest point) is not part of the rule — a hold re-published at
  rest would never time out and never give the operator back.
* **selection** — hold while its last message is at most `hold_timeout` old, else operator. The
  timeout is the only hysteresis, as in twist_mux: after the last hold message the operator gets
  control back `hold_timeout` later.
* **the hold command** — when hold becomes selected, the pose q_hold is latched; while it stays
  selected, a critically damped computed-torque PD holds it:
  u = M̂(q) (−ω² (q − q_hold) − 2ω q̇) + Ĉ(q, q̇) q̇ + ĝ(q), ω = `hold_bandwidth` (10 rad/s).
  M̂, Ĉ, ĝ use the nominal parameters (by default the true θ: the mux is given the model the
  shared law has to learn). From an approach at speed s caught on the f_b2 curve
  (s·b2²/(1 + s·b2) from the face), the overshoot past q_hold is at most s/(ω e); it is smaller
  than the distance left for every s below ~14 m/s with b2 = 0.6.

The mux keeps the robot inside by stopping it, not by steering it: what the operator asks for
near a face is dropped, so tracking along a face is stop-and-go.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..constraints import FeasibleSet
from ..sets import Bands, allowance, hazardous_rows
from .strategy import Command, NominalModel, Strategy, checked

OPERATOR, HOLD = 0, 1   # Command.mode: the selected input


@dataclass(frozen=True)
class MuxState:
    since_hold_message: float = math.inf   # s since the border monitor last published
    q_hold: np.ndarray | None = None       # the latched pose while hold is selected


@dataclass
class PriorityMux(Strategy):
    feasible: FeasibleSet
    bands: Bands
    nominal: NominalModel
    hold_timeout: float = 0.5      # s
    hold_bandwidth: float = 10.0   # ω, rad/s
    name: str = "mux"

    def initial_state(self, q0, v0):
        return MuxState()

    def near_border(self, q: np.ndarray, v: np.ndarray) -> bool:
        """The border monitor's rule: the state is not SAFE by Definition 2 with b0 (no standoff band):
        no polytope containing q has every row either farther than b2 from its face or approaching it no
        faster than f_b2, and none hazardous (sets.hazardous_rows: within b1 at f_b1, or within b0 at all)."""
        b2 = self.bands.b2
        for poly in self.feasible.regions:
            x = poly.values(q)
            if not np.all(x < 0.0):
                continue
            x_dot = poly.K @ v
            if not np.any(((x >= -b2) & (x_dot > allowance(x, b2))) | hazardous_rows(x, x_dot, self.bands)):
                return False
        return True

    def step(self, state: MuxState, q, v, operator, dt):
        u_h = np.asarray(operator.force, float)
        since = 0.0 if self.near_border(q, v) else state.since_hold_message + dt
        if since > self.hold_timeout:
            return MuxState(since, None), Command(checked(u_h), u_h, True, OPERATOR)
        q_hold = np.array(q, float) if state.q_hold is None else state.q_hold
        w = self.hold_bandwidth
        u = self.nominal.mass(q) @ (-w * w * (q - q_hold) - 2.0 * w * v) + self.nominal.bias(q, v)
        return MuxState(since, q_hold), Command(checked(u), u_h, False, HOLD)
