"""Per-robot summaries accumulated while a batch runs, and (optionally) full traces.

`metrics.summarize` reads a finished Trace; a batch of thousands of robots cannot keep every
trace, so `Tally` folds each recorded row into running figures that give the same fields:
violations, min_margin, tracking_rmse, final_error, human_authority, switches, group_switches,
min_dwell, theta_hat, transparency, law_share, theta_error, finite, steps, duration. `Recording`
keeps the Trace columns instead, for a comparison with the scalar simulator.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..metrics import equal_inputs, theta_error
from ..sets import SetClass
from ..simulator import Trace
from . import plant

HUMAN = 0
SAFE = int(SetClass.SAFE)


@dataclass
class Rows:
    """One recorded row (the simulator's sample at the start of a step) for some robots."""

    t: float
    q: np.ndarray          # (n, M)
    v: np.ndarray
    q_r: np.ndarray
    u_s: np.ndarray
    theta_hat: np.ndarray  # (n_θ, M): the estimate the active law stands for
    authority: np.ndarray  # (M,) −1 on a row recorded at an escape
    margin: np.ndarray
    inside: np.ndarray
    # the remaining Trace columns (v_hat, q_d, u_h, u_f, set_class, group, role, k_h, k_f, intent,
    # true_class, own_law)
    extra: dict


@dataclass
class Tally:
    """Running summary figures, one entry per robot of a chunk (arrays (M,) or (n_θ, M))."""

    rows: np.ndarray
    violations: np.ndarray
    min_margin: np.ndarray
    err_sq: np.ndarray
    err_count: np.ndarray
    final_error: np.ndarray
    human_rows: np.ndarray
    last_human: np.ndarray
    last_change: np.ndarray
    min_dwell_steps: np.ndarray
    rows_finite: np.ndarray
    theta_hat: np.ndarray
    safe_rows: np.ndarray          # rows with the true state in O_s …
    transparent_rows: np.ndarray   # … and u_s = u_h there (metrics.equal_inputs)
    machine_rows: np.ndarray       # rows with machine authority (MACHINE or SHARED) …
    own_law_rows: np.ndarray       # … and u_f from the configuration's own law

    @staticmethod
    def empty(M: int, n_theta: int) -> "Tally":
        return Tally(np.zeros(M, np.int64), np.zeros(M, np.int64), np.full(M, np.inf), np.zeros(M),
                     np.zeros(M, np.int64), np.full(M, np.nan), np.zeros(M, np.int64), np.zeros(M, bool),
                     np.full(M, -1, np.int64),
                     np.full(M, np.iinfo(np.int64).max), np.ones(M, bool), np.full((n_theta, M), np.nan),
                     *(np.zeros(M, np.int64) for _ in range(4)))

    def take(self, index) -> "Tally":
        return Tally(*(getattr(self, f.name)[..., index] for f in fields(self)))

    def add(self, r: Rows, cols=slice(None)) -> None:
        """Fold one row per robot `cols` (slice or index array) into the figures."""
        row = self.rows[cols]
        err = np.sqrt(np.sum((r.q - r.q_r) ** 2, axis=0))
        good = np.isfinite(err)
        human = r.authority == HUMAN
        changed = (row > 0) & (human != self.last_human[cols])
        last = self.last_change[cols]
        self.min_dwell_steps[cols] = np.where(changed & (last >= 0), np.minimum(self.min_dwell_steps[cols], row - last),
                                              self.min_dwell_steps[cols])
        self.last_change[cols] = np.where(changed, row, last)
        self.last_human[cols] = human
        self.violations[cols] += ~r.inside
        self.min_margin[cols] = np.minimum(self.min_margin[cols], r.margin)
        self.err_sq[cols] += np.where(good, err * err, 0.0)
        self.err_count[cols] += good
        self.final_error[cols] = np.where(good, err, self.final_error[cols])
        self.human_rows[cols] += human
        self.rows_finite[cols] &= np.all(np.isfinite(r.q) & np.isfinite(r.v) & np.isfinite(r.u_s), axis=0)
        self.theta_hat[:, cols] = r.theta_hat
        safe = r.extra["true_class"] == SAFE
        self.safe_rows[cols] += safe
        self.transparent_rows[cols] += safe & equal_inputs(r.u_s, r.extra["u_h"], axis=0)
        machine = r.authority > HUMAN                 # MACHINE or SHARED (−1 on a row recorded at an escape)
        self.machine_rows[cols] += machine
        self.own_law_rows[cols] += machine & r.extra["own_law"]
        self.rows[cols] = row + 1


@dataclass
class BatchResult:
    """Every robot's summary (arrays over the batch) and, if recorded, its trace."""

    dt: float
    steps: np.ndarray
    violations: np.ndarray
    min_margin: np.ndarray
    tracking_rmse: np.ndarray
    final_error: np.ndarray
    human_authority: np.ndarray
    switches: np.ndarray
    group_switches: np.ndarray
    min_dwell: np.ndarray          # s, NaN where fewer than two authority changes
    theta_hat: np.ndarray          # (N, n_θ)
    transparency: np.ndarray       # NaN where no sample was safe
    law_share: np.ndarray          # NaN where the machine never had authority
    finite: np.ndarray
    recording: "Recording | None" = None
    theta: np.ndarray | None = None   # (N, n_θ) the plants' true θ

    @property
    def size(self) -> int:
        return self.steps.size

    def summary(self, i: int) -> dict:
        """Robot i's summary, the same fields (and meanings) as metrics.summarize."""
        dwell = self.min_dwell[i]
        return {
            "violations": int(self.violations[i]),
            "min_margin": float(self.min_margin[i]),
            "tracking_rmse": float(self.tracking_rmse[i]),
            "final_error": float(self.final_error[i]),
            "human_authority": float(self.human_authority[i]),
            "switches": int(self.switches[i]),
            "group_switches": int(self.group_switches[i]),
            "min_dwell": None if np.isnan(dwell) else float(dwell),
            "theta_hat": [float(x) for x in self.theta_hat[i]],
            "transparency": None if np.isnan(self.transparency[i]) else float(self.transparency[i]),
            "law_share": None if np.isnan(self.law_share[i]) else float(self.law_share[i]),
            "theta_error": theta_error(self.theta_hat[i], None if self.theta is None else self.theta[i]),
            "finite": bool(self.finite[i]),
            "steps": int(self.steps[i]),
            "duration": float(self.steps[i] * self.dt),
        }

    def summaries(self) -> list[dict]:
        return [self.summary(i) for i in range(self.size)]

    def trace(self, i: int, model) -> Trace:
        """Robot i's Trace (needs `record=True`); `model` gives the wheel torques."""
        if self.recording is None:
            raise ValueError("this batch was run without record=True")
        return self.recording.trace(i, int(self.steps[i]), bool(self.finite_flag[i]), int(self.switches[i]),
                                    int(self.group_switches[i]), model,
                                    model.theta if self.theta is None else self.theta[i])

    finite_flag: np.ndarray | None = None   # Trace.finite (no non-finite state was integrated)


def finish(dt: float, tally: Tally, switches, group_switches, trace_finite, recording=None,
           theta=None) -> BatchResult:
    """Turn the (flushed, whole-batch) tally into per-robot summaries; `theta` (n_θ, N): the true θ."""
    rows = tally.rows
    with np.errstate(invalid="ignore", divide="ignore"):
        rmse = np.where(tally.err_count > 0, np.sqrt(tally.err_sq / np.maximum(tally.err_count, 1)), np.nan)
    unset = tally.min_dwell_steps == np.iinfo(np.int64).max
    dwell = np.where(unset, np.nan, tally.min_dwell_steps.astype(float) * dt)
    with np.errstate(invalid="ignore", divide="ignore"):
        transparency = np.where(tally.safe_rows > 0, tally.transparent_rows / np.maximum(tally.safe_rows, 1), np.nan)
        law_share = np.where(tally.machine_rows > 0, tally.own_law_rows / np.maximum(tally.machine_rows, 1), np.nan)
    return BatchResult(
        dt=dt, steps=rows.copy(), violations=tally.violations.copy(),
        min_margin=np.where(rows > 0, tally.min_margin, np.nan), tracking_rmse=rmse,
        final_error=tally.final_error.copy(),
        human_authority=np.where(rows > 0, tally.human_rows / np.maximum(rows, 1), 0.0),
        switches=np.asarray(switches).copy(), group_switches=np.asarray(group_switches).copy(), min_dwell=dwell,
        theta_hat=tally.theta_hat.T.copy(), transparency=transparency, law_share=law_share,
        finite=np.asarray(trace_finite) & tally.rows_finite,
        recording=recording, theta=None if theta is None else np.asarray(theta, float).T.copy(),
        finite_flag=np.asarray(trace_finite).copy(),
    )


_VECTORS = ("q", "v", "v_hat", "q_d", "q_r", "u_h", "u_f", "u_s")
_SCALARS = ("k_h", "k_f", "intent", "margin")
_LABELS = ("authority", "set_class", "group", "role", "true_class")


class Recording:
    """Trace columns for every robot: arrays (steps, …, N)."""

    def __init__(self, steps: int, n: int, n_theta: int, N: int):
        self.t = np.full((steps, N), np.nan)
        self.cols = {k: np.full((steps, n, N), np.nan) for k in _VECTORS}
        self.cols["theta_hat"] = np.full((steps, n_theta, N), np.nan)
        self.cols.update({k: np.full((steps, N), np.nan) for k in _SCALARS})
        self.cols.update({k: np.full((steps, N), -1, dtype=int) for k in _LABELS})
        self.cols["inside"] = np.zeros((steps, N), dtype=bool)
        self.cols["own_law"] = np.zeros((steps, N), dtype=bool)

    def put(self, k: int, ids: np.ndarray, r: Rows) -> None:
        self.t[k, ids] = r.t
        values = {"q": r.q, "v": r.v, "q_r": r.q_r, "u_s": r.u_s, "theta_hat": r.theta_hat, "authority": r.authority,
                  "margin": r.margin, "inside": r.inside, **r.extra}
        for name, value in values.items():
            self.cols[name][k, ..., ids] = value.T if np.ndim(value) == 2 else value

    def trace(self, i: int, steps: int, finite: bool, switches: int, group_switches: int, model,
              theta=None) -> Trace:
        cols = {name: (arr[:steps, ..., i]) for name, arr in self.cols.items()}
        tau = plant.wheel_torques(cols["q"], cols["u_s"], model)
        return Trace(t=self.t[:steps, i], tau=tau, **cols, finite=finite, switches=switches,
                     group_switches=group_switches, theta=theta)
