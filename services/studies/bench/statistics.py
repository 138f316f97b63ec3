"""Summary statistics of timing samples (pure): percentiles, period jitter, deadline misses."""
from __future__ import annotations

import math

import numpy as np


def percentiles(samples, scale: float = 1.0) -> dict:
    """{"p50", "p99", "median", "max", "n"} of `samples` × `scale` (NaN when there are none)."""
    arr = np.asarray(samples, dtype=float) * scale
    if arr.size == 0:
        return {"p50": math.nan, "median": math.nan, "p99": math.nan, "max": math.nan, "n": 0}
    p50, p99 = np.percentile(arr, [50.0, 99.0])
    return {"p50": float(p50), "median": float(p50), "p99": float(p99), "max": float(arr.max()), "n": int(arr.size)}


def intervals(times) -> np.ndarray:
    """Differences between consecutive event times."""
    return np.diff(np.asarray(times, dtype=float))


def period_jitter(times, period: float) -> np.ndarray:
    """|Δt − T| of consecutive events that were meant to be `period` apart."""
    return np.abs(intervals(times) - period)


def missed_periods(times, period: float) -> int:
    """Periods with no event: an interval of k·T (k ≥ 2, rounded) means k − 1 missed deadlines."""
    gaps = intervals(times) / period
    return int(np.sum(np.maximum(np.rint(gaps) - 1.0, 0.0)))


def group_bursts(times, gap: float) -> list[float]:
    """The first time of each burst: events closer than `gap` to the previous one belong to its burst."""
    out: list[float] = []
    last = -math.inf
    for t in times:
        if t - last > gap:
            out.append(t)
        last = t
    return out
