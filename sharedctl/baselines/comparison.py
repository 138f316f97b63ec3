"""One loop for every strategy: the plant integrated finely, the strategy sampled at the daemon's rate.

Why sampled (like sampled.py) rather than the continuous simulator: the controller daemon runs at
500 Hz with the operator's commands arriving late, lost or stale, and a mux timeout or a QP are
discrete-time things; sampling every strategy at the same 2 ms with the same operator link
(operator_link.py) compares them as they would run on the robot. The plant is integrated by
RK4 at `control_period / substeps` with the force held (zero-order hold), exactly as sampled.py.

`build_strategy(name, loop)` makes `human`, `mux`, `cbf`, `shared` or `shared-nobackup` (the shared law
without the scenario's backup-safe sets) for a scenario's closed loop.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..sampled import hold_and_integrate
from ..shared_controller import NonFiniteCommand
from ..simulator import ClosedLoop
from .cbf import CbfSafetyFilter
from .mux import PriorityMux
from .operator_link import IDEAL, LinkConditions, OperatorLink
from .strategy import NominalModel, OperatorAlone, SharedStrategy, Strategy

STRATEGIES = ("human", "mux", "cbf", "shared", "shared-nobackup")
CONTROL_PERIOD = 0.002   # s, the daemon's 500 Hz


def build_strategy(name: str, loop: ClosedLoop, theta: np.ndarray | None = None) -> Strategy:
    """A strategy for this closed loop; `theta` the nominal parameters of mux and cbf (default: the true θ)."""
    if name == "human":
        return OperatorAlone()
    if name in ("shared", "shared-nobackup"):
        return SharedStrategy.of(loop, backup=name == "shared")
    nominal = NominalModel.of(loop.model, theta)
    if name == "mux":
        return PriorityMux(loop.feasible, loop.sharing.bands, nominal)
    if name == "cbf":
        return CbfSafetyFilter(loop.feasible, nominal)
    raise ValueError(f"unknown strategy {name!r} (expected one of {', '.join(STRATEGIES)})")


@dataclass
class ComparisonTrace:
    """Per control period (at the start of the period)."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    u: np.ndarray            # applied generalised force
    u_h: np.ndarray          # the operator's force as received (hands-off: 0)
    acceleration: np.ndarray  # q̈ at the sample, under the applied force
    wish: np.ndarray         # the operator's true wish q_d(t) (not delayed)
    operator_in_control: np.ndarray
    hands_off: np.ndarray
    mode: np.ndarray
    residual: np.ndarray
    margin: np.ndarray
    inside: np.ndarray
    finite: bool
    commands_sent: int
    commands_lost: int


def run(strategy: Strategy, loop: ClosedLoop, q0, v0, duration: float, conditions: LinkConditions = IDEAL,
        control_period: float = CONTROL_PERIOD, substeps: int = 4) -> ComparisonTrace:
    """Run one strategy on one closed loop (its model, feasible set and operator) under one link condition."""
    model, feasible, human = loop.model, loop.feasible, loop.human
    link = OperatorLink(human, conditions)
    n = model.n
    steps = max(1, int(round(duration / control_period)))
    cols = {k: np.full((steps, n), np.nan) for k in ("q", "v", "u", "u_h", "acceleration", "wish")}
    flags = {k: np.zeros(steps, dtype=bool) for k in ("operator_in_control", "hands_off", "inside")}
    mode = np.full(steps, -1, dtype=int)
    t_col, residual, margin = np.full(steps, np.nan), np.full(steps, np.nan), np.full(steps, np.nan)
    q, v = np.asarray(q0, float).copy(), np.asarray(v0, float).copy()
    state = strategy.initial_state(q, v)
    h = control_period / substeps
    finite, k = True, 0
    for k in range(steps):
        t = k * control_period
        operator, hands_off = link.input_at(t, q, v)
        try:
            state, cmd = strategy.step(state, q, v, operator, control_period)
        except NonFiniteCommand:
            finite = False
            break
        u = cmd.u
        t_col[k], mode[k], residual[k] = t, cmd.mode, cmd.residual
        cols["q"][k], cols["v"][k], cols["u"][k], cols["u_h"][k] = q, v, u, cmd.u_h
        cols["acceleration"][k] = model.acceleration(q, v, u)
        cols["wish"][k] = human.desired(t).q
        flags["operator_in_control"][k], flags["hands_off"][k] = cmd.operator_in_control, hands_off
        margin[k], flags["inside"][k] = feasible.margin(q), feasible.contains(q)
        q, v = hold_and_integrate(model, q, v, u, h, substeps)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            finite = False
            k += 1
            break
    else:
        k = steps
    cut = {name: arr[:k] for name, arr in {**cols, **flags}.items()}
    return ComparisonTrace(t=t_col[:k], mode=mode[:k], residual=residual[:k], margin=margin[:k], finite=finite,
                           commands_sent=link.sent, commands_lost=link.lost, **cut)
