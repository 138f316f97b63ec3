"""The metrics of one comparison run (the `sharedctl compare --json` row; fields may be added, not renamed).

* violations — samples with q in no polytope of the feasible set (0 is the requirement);
* min_margin — min over time of the best polytope's smallest slack −(K q + T), m (< 0: outside);
* tracking_error — the RMS over time of |q − Π(q_d)|, where q_d(t) is the operator's true wish
  (the human model's, not the delayed copy the controller holds) and Π the Euclidean projection
  onto the feasible set (the nearest point of the nearest polytope): how far the robot is from
  the best it could do for the operator without leaving the set. All coordinates (m and rad);
* time_to_goal — the first sample time t_k from which |q − Π(q_d)| ≤ GOAL_TOLERANCE holds at every
  sample to the end of the run (s; 0 if it holds from the start), with Π(q_d) as in tracking_error
  at the same instant: for a wish that comes to rest, the time to reach its projected end point and
  stay there; for a moving wish, the time from which the robot follows it within the tolerance.
  Null when the last sample is farther than the tolerance or the run was cut short (not finite);
* human_authority — fraction of samples where the operator's force passed unchanged (u = u_h);
* interventions — how often the strategy took the operator's force away (u = u_h → u ≠ u_h);
* control_effort — ∫ |u|² dt over the run, N² s;
* jerk_rms — RMS of |q̈(t_{k+1}) − q̈(t_k)| / Δt over consecutive samples, under the applied
  force (the held force changes only at samples, so this is the jerk the robot feels per period);
* hands_off — fraction of samples with the operator's input stale (> 0.3 s) or not yet arrived;
* max_residual — the largest QP constraint residual max(A u − b) (cbf only, else null).
"""
from __future__ import annotations

import numpy as np
import quadprog

from ..constraints import FeasibleSet
from .comparison import ComparisonTrace

#: time_to_goal's tolerance on |q − Π(q_d)| (m and rad in one norm): above √2·ε = 0.071 m, the offset of the
#: machine's projected reference from a corner of two faces (ε = 0.05 m, reference.py), so a robot held at
#: the reference the machine can reach counts as arrived
GOAL_TOLERANCE = 0.1


def project(feasible: FeasibleSet, point: np.ndarray) -> np.ndarray:
    """The nearest point of the union ∪ {K q + T ≤ 0} to `point` (per polytope: a QP)."""
    best, best_d = None, np.inf
    for poly in feasible.regions:
        if np.all(poly.values(point) <= 0.0):
            return point.copy()
        # min ½|p − point|²  s.t.  −K p ≥ T
        p = quadprog.solve_qp(np.eye(point.size), point, -poly.K.T, poly.T, 0)[0]
        d = float(np.linalg.norm(p - point))
        if d < best_d:
            best, best_d = p, d
    return best


def summarize(trace: ComparisonTrace, feasible: FeasibleSet, control_period: float) -> dict:
    steps = int(trace.t.size)
    if steps == 0:
        return {"violations": 0, "min_margin": None, "tracking_error": None, "time_to_goal": None,
                "human_authority": None, "interventions": 0, "control_effort": 0.0, "jerk_rms": None,
                "hands_off": None, "max_residual": None, "finite": bool(trace.finite), "steps": 0, "duration": 0.0}
    projected = _projected_wishes(feasible, trace.wish)
    err = np.linalg.norm(trace.q - projected, axis=1)
    passed = trace.operator_in_control
    taken = int(np.count_nonzero(passed[:-1] & ~passed[1:])) + int(not passed[0])
    jerk = np.linalg.norm(np.diff(trace.acceleration, axis=0), axis=1) / control_period
    residual = trace.residual[np.isfinite(trace.residual)]
    return {
        "violations": int(np.count_nonzero(~trace.inside)),
        "min_margin": float(np.min(trace.margin)),
        "tracking_error": float(np.sqrt(np.mean(err**2))),
        "time_to_goal": time_to_goal(trace.t, err, GOAL_TOLERANCE) if trace.finite else None,
        "human_authority": float(np.mean(passed)),
        "interventions": taken,
        "control_effort": float(np.sum(np.sum(trace.u**2, axis=1)) * control_period),
        "jerk_rms": float(np.sqrt(np.mean(jerk**2))) if jerk.size else 0.0,
        "hands_off": float(np.mean(trace.hands_off)),
        "max_residual": float(np.max(residual)) if residual.size else None,
        "finite": bool(trace.finite and np.all(np.isfinite(trace.u))),
        "steps": steps,
        "duration": float(steps * control_period),
    }


def time_to_goal(t: np.ndarray, distance: np.ndarray, tolerance: float) -> float | None:
    """The first t_k with distance ≤ tolerance at every sample from k to the end; None if not at the last."""
    away = np.flatnonzero(~(distance <= tolerance))          # NaN counts as away
    if away.size == 0:
        return float(t[0])
    if away[-1] == distance.size - 1:
        return None
    return float(t[away[-1] + 1])


def _projected_wishes(feasible: FeasibleSet, wishes: np.ndarray) -> np.ndarray:
    out = np.empty_like(wishes)
    last_wish, last = None, None
    for k, w in enumerate(wishes):
        if last_wish is not None and np.array_equal(w, last_wish):
            out[k] = last                        # a held wish (e.g. a fixed target) is projected once
            continue
        last_wish, last = w, project(feasible, w)
        out[k] = last
    return out
