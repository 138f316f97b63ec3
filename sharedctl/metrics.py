"""The summary of one run (the `sharedctl sim --json` contract; fields may be added, not renamed)."""
from __future__ import annotations

import numpy as np

from .sets import SetClass
from .sharing import Authority
from .simulator import Trace

#: u_s counts as u_h when |u_s − u_h| ≤ TRANSPARENCY_RTOL · max(|u_h|, tiny) (the transparency figure)
TRANSPARENCY_RTOL = 1e-9


def summarize(trace: Trace, dt: float) -> dict:
    """violations, min_margin, tracking_rmse, final_error, human_authority, switches, group_switches,
    min_dwell, theta_hat, transparency, law_share, theta_error, finite, steps, duration.

    * violations: samples where q is in no region of the feasible set;
    * min_margin: min over time of the best region's smallest slack −(K q + T) (unit rows);
    * tracking_rmse / final_error: |q − q_r| against the machine's projected reference q_r
      (of the active group, or of the group the machine would pick);
    * human_authority: fraction of samples with u_s = u_h (k_s = 1);
    * switches: authority changes (human ↔ machine);
    * transparency: among the samples whose true state (q, q̇) — not the observer's v̂ — is in
      the safe set O_s (Definition 2), the share in which u_s = u_h (to TRANSPARENCY_RTOL,
      relative). Below 1 within the minimum dwell of a machine intervention (docs/control.md §6,
      item 4) and, under output feedback, where (47) classifies (q, v̂) otherwise. None when no
      sample is safe or the trace does not record the true class;
    * law_share: among the samples with machine authority (k_s = 0: MACHINE or SHARED), the
      share whose u_f came from the configuration's own law (MachineController.tracking), as
      the trace records which law ran; a fallback to another law (the hazard role's (12)) does
      not count. None when the machine never had authority or the trace does not record it;
    * theta_error: |θ̂ − θ| / |θ| with the final θ̂ (the `theta_hat` field: the estimate the
      active law stands for) and the plant's true θ (Trace.theta). None where θ is unknown.
    """
    steps = int(trace.t.size)
    err = np.linalg.norm(trace.q - trace.q_r, axis=1)
    err = err[np.isfinite(err)]
    dwell = authority_dwell_times(trace, dt)
    return {
        "violations": int(np.count_nonzero(~trace.inside)),
        "min_margin": float(np.min(trace.margin)) if steps else float("nan"),
        "tracking_rmse": float(np.sqrt(np.mean(err**2))) if err.size else float("nan"),
        "final_error": float(err[-1]) if err.size else float("nan"),
        "human_authority": float(np.mean(trace.authority == int(Authority.HUMAN))) if steps else 0.0,
        "switches": int(trace.switches),
        "group_switches": int(trace.group_switches),
        "min_dwell": float(min(dwell)) if dwell else None,
        "theta_hat": [float(x) for x in trace.theta_hat[-1]] if steps else [],
        "transparency": transparency(trace),
        "law_share": law_share(trace),
        "theta_error": theta_error(trace.theta_hat[-1], trace.theta) if steps else None,
        "finite": bool(trace.finite and all(np.all(np.isfinite(a)) for a in (trace.q, trace.v, trace.u_s))),
        "steps": steps,
        "duration": float(steps * dt),
    }


def equal_inputs(u_s: np.ndarray, u_h: np.ndarray, axis: int = -1) -> np.ndarray:
    """Per sample: |u_s − u_h| ≤ TRANSPARENCY_RTOL · max(|u_h|, tiny) (norms along `axis`; False on NaN)."""
    gap = np.linalg.norm(u_s - u_h, axis=axis)
    scale = np.maximum(np.linalg.norm(u_h, axis=axis), np.finfo(float).tiny)
    return gap <= TRANSPARENCY_RTOL * scale


def transparency(trace: Trace) -> float | None:
    """Share of the samples with the true state in O_s in which u_s = u_h (None: none such, or unrecorded)."""
    if trace.true_class is None:
        return None
    safe = trace.true_class == int(SetClass.SAFE)
    if not safe.any():
        return None
    return float(np.mean(equal_inputs(trace.u_s[safe], trace.u_h[safe])))


def law_share(trace: Trace) -> float | None:
    """Share of the samples with machine authority whose u_f came from the configuration's own law."""
    if trace.own_law is None:
        return None
    machine = (trace.authority == int(Authority.MACHINE)) | (trace.authority == int(Authority.SHARED))
    if not machine.any():
        return None
    return float(np.mean(trace.own_law[machine]))


def theta_error(theta_hat: np.ndarray, theta: np.ndarray | None) -> float | None:
    """|θ̂ − θ| / |θ| (None where θ is unknown or zero)."""
    if theta is None:
        return None
    scale = float(np.linalg.norm(theta))
    if scale == 0.0:
        return None
    return float(np.linalg.norm(np.asarray(theta_hat, float) - theta) / scale)


def authority_dwell_times(trace: Trace, dt: float) -> list[float]:
    """Time spent between consecutive changes of k_s (human ↔ machine), in seconds."""
    human = trace.authority == int(Authority.HUMAN)
    changes = np.flatnonzero(human[1:] != human[:-1]) + 1
    return [float(b - a) * dt for a, b in zip(changes[:-1], changes[1:])]
