"""The summary of one run (the `sharedctl sim --json` contract; fields may be added, not renamed)."""
from __future__ import annotations

import numpy as np

from .sharing import Authority
from .simulator import Trace


def summarize(trace: Trace, dt: float) -> dict:
    """violations, min_margin, tracking_rmse, final_error, human_authority, switches, theta_hat, finite, steps,
    duration.

    * violations: samples where q is in no region of the feasible set;
    * min_margin: min over time of the best region's smallest slack −(K q + T) (unit rows);
    * tracking_rmse / final_error: |q − q_r| against the machine's projected reference q_r
      (of the active group, or of the group the machine would pick);
    * human_authority: fraction of samples with u_s = u_h (k_s = 1);
    * switches: authority changes (human ↔ machine).
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
        "finite": bool(trace.finite and all(np.all(np.isfinite(a)) for a in (trace.q, trace.v, trace.u_s))),
        "steps": steps,
        "duration": float(steps * dt),
    }


def authority_dwell_times(trace: Trace, dt: float) -> list[float]:
    """Time spent between consecutive changes of k_s (human ↔ machine), in seconds."""
    human = trace.authority == int(Authority.HUMAN)
    changes = np.flatnonzero(human[1:] != human[:-1]) + 1
    return [float(b - a) * dt for a, b in zip(changes[:-1], changes[1:])]
