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
      item 4), while the operator still pushes at a face the machine took over at (item 1) and,
      under output feedback, where (47) classifies (q, v̂) otherwise. None when no
      sample is safe or the trace does not record the true class;
    * law_share: among the samples with machine authority (k_s = 0: MACHINE or SHARED), the
      share whose u_f came from a law of the configuration (MachineController.owns: the `of`
      barrier law counts for `of`), as the trace records which law ran; a fallback to another
      configuration's law (e.g. (12) under `of`) does not count. None when the machine never had
      authority or the trace does not record it;
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


#: a sample-to-sample change of u_s larger than this share of the run's peak |u_s| is a force jump
FORCE_JUMP_SHARE = 0.25


def handover(trace: Trace) -> dict:
    """excursions, max_switches_per_excursion, force_jumps, peak_wheel_torque — the hand-over's figures,
    from a whole trace (`sharedctl sim --json` adds them to the summary; the batched simulator, which
    keeps no trace, does not).

    * excursions: times the operator's wish left the admissible set (Trace.wish_inside turning
      False; a run starting outside counts one);
    * max_switches_per_excursion: authority changes counted from each excursion's start to the next
      one's (to the end for the last), the largest count; None without an excursion;
    * force_jumps: samples where |u_s(k+1) − u_s(k)| exceeds FORCE_JUMP_SHARE of the run's peak
      |u_s| — every edge of a pulse train counts, a smooth hand-over has one at the take-over and
      one at the release;
    * peak_wheel_torque: the largest |τ| (wheel torques for a wheeled robot, u_s otherwise).
    """
    human = trace.authority == int(Authority.HUMAN)
    changes = np.flatnonzero(human[1:] != human[:-1]) + 1
    starts = []
    if trace.wish_inside is not None and trace.wish_inside.size:
        outside = ~trace.wish_inside
        starts = np.flatnonzero(outside[1:] & ~outside[:-1]) + 1
        starts = ([0] if outside[0] else []) + starts.tolist()
    bounds = starts + [trace.t.size]
    per = [int(np.count_nonzero((changes >= a) & (changes < b))) for a, b in zip(bounds[:-1], bounds[1:])]
    rows = trace.u_s[np.all(np.isfinite(trace.u_s), axis=1)]
    peak = float(np.linalg.norm(rows, axis=1).max()) if rows.size else 0.0
    steps = np.linalg.norm(np.diff(rows, axis=0), axis=1) if len(rows) > 1 else np.zeros(0)
    torque = np.abs(trace.tau[np.all(np.isfinite(trace.tau), axis=1)])
    return {
        "excursions": len(starts),
        "max_switches_per_excursion": max(per) if per else None,
        "force_jumps": int(np.count_nonzero(steps > FORCE_JUMP_SHARE * peak)) if peak > 0 else 0,
        "peak_wheel_torque": float(torque.max()) if torque.size else None,
    }


def authority_dwell_times(trace: Trace, dt: float) -> list[float]:
    """Time spent between consecutive changes of k_s (human ↔ machine), in seconds."""
    human = trace.authority == int(Authority.HUMAN)
    changes = np.flatnonzero(human[1:] != human[:-1]) + 1
    return [float(b - a) * dt for a, b in zip(changes[:-1], changes[1:])]


def peak_norm(signal: np.ndarray) -> float | None:
    """max over samples of |signal(t)| (Euclidean norm of each row; rows with a NaN skipped; None: no such row)."""
    norms = _finite_row_norms(signal)
    return float(norms.max()) if norms.size else None


def rms_norm(signal: np.ndarray) -> float | None:
    """√(mean over samples of |signal(t)|²) (rows with a NaN skipped; None: no such row)."""
    norms = _finite_row_norms(signal)
    return float(np.sqrt(np.mean(norms**2))) if norms.size else None


def share_above(signal: np.ndarray, limit: float) -> float | None:
    """Share of the samples (rows with a NaN skipped) in which some component has |signal_j(t)| > limit."""
    rows = np.asarray(signal, dtype=float).reshape(len(signal), -1)
    rows = rows[np.all(np.isfinite(rows), axis=1)]
    return float(np.mean(np.any(np.abs(rows) > limit, axis=1))) if rows.size else None


def machine_authority_time(trace: Trace, dt: float) -> float:
    """Time (s) with full machine authority (k_s = 0, k_h = 0: u_s = u_f) — the only samples in which θ̂
    adapts (docs/control.md §6, item 7)."""
    return float(np.count_nonzero(trace.authority == int(Authority.MACHINE)) * dt)


def _finite_row_norms(signal: np.ndarray) -> np.ndarray:
    rows = np.asarray(signal, dtype=float).reshape(len(signal), -1)
    return np.linalg.norm(rows[np.all(np.isfinite(rows), axis=1)], axis=1)
