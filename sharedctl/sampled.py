"""Sampled-data simulation: the plant integrated finely, the shared controller sampled.

This is what the distributed system does — the controller reads (q, q̇) every control period,
computes u_s with `SharedController.step` and holds it — without processes or a network.
It is the in-process reference the distributed run is compared with.
"""
from __future__ import annotations

import numpy as np

from .metrics import summarize  # noqa: F401 — re-exported for callers comparing runs
from .shared_controller import OperatorInput, SharedController
from .simulator import ClosedLoop, Trace, _Recorder


def hold_and_integrate(model, q, v, u, h: float, substeps: int):
    """The plant over one control period: `substeps` RK4 steps of length h with u held (zero-order hold)."""
    for _ in range(substeps):
        a1 = model.acceleration(q, v, u)
        a2 = model.acceleration(q + h / 2 * v, v + h / 2 * a1, u)
        a3 = model.acceleration(q + h / 2 * (v + h / 2 * a1), v + h / 2 * a2, u)
        a4 = model.acceleration(q + h * (v + h / 2 * a2), v + h * a3, u)
        q = q + h * v + h * h / 6 * (a1 + a2 + a3)
        v = v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
    return q, v


def simulate_sampled(loop: ClosedLoop, q0, v0, duration: float, control_period: float, substeps: int = 4) -> Trace:
    """Plant RK4 at control_period/substeps with u_s held; controller stepped every control_period."""
    model, human = loop.model, loop.human
    ctrl = SharedController(model, loop.feasible, loop.controller, loop.sharing, loop.reference, loop.backup)
    state = ctrl.initial_state(q0, loop.theta_hat0)
    q, v = np.asarray(q0, float).copy(), np.asarray(v0, float).copy()
    steps = int(round(duration / control_period))
    h = control_period / substeps
    rec = _Recorder(steps, model.n, model.n_theta)
    is_omni = hasattr(model, "wheel_torques")
    finite = True
    k = 0
    for k in range(steps):
        t = k * control_period
        cmd = human.command(t, q, v)
        operator = OperatorInput(human.desired(t), cmd.force, cmd.intent)
        state, out = ctrl.step(state, q, None if loop.controller.observer else v, operator, control_period)
        rec.put(
            k, t=t, q=q, v=v, v_hat=out.v_used, q_d=operator.desired.q, q_r=out.q_r, u_h=out.u_h, u_f=out.u_f,
            u_s=out.u_s, tau=model.wheel_torques(q, out.u_s) if is_omni else out.u_s, theta_hat=out.theta_estimate,
            authority=int(out.authority), set_class=int(out.set_class), group=-1 if out.group is None else out.group,
            role=int(out.role), k_h=out.k_h, k_f=out.k_f, intent=cmd.intent, margin=loop.feasible.margin(q),
            inside=loop.feasible.contains(q),
        )
        u = out.u_s
        q, v = hold_and_integrate(model, q, v, u, h, substeps)
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            finite = False
            k += 1
            break
    else:
        k = steps
    return rec.trace(k, finite, state.arbiter.switches, state.arbiter.group_switches)
