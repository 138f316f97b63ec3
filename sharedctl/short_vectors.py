"""Linear algebra on short vectors held as lists or tuples of Python floats.

The control step works on vectors of n = 2 or 3 entries and matrices of a few rows. There a
numpy call costs 0.3–1 µs whatever it computes, while a Python float operation costs ≈ 10 ns:
the step's per-sample arithmetic (transform.py, the laws, the classification) is therefore
written on floats, and numpy is kept for set-up and for evaluating many rows at once
(docs/performance.md, "The control step"). These helpers work for any length, with the
length 3 (the omnidirectional robot) written out: a generic `sum(map(mul, a, b))` costs twice
the arithmetic it does. Products are summed left to right.
"""
from __future__ import annotations

from operator import mul

import numpy as np


def dot(a, b) -> float:
    """aᵀb."""
    if len(a) == 3:
        return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    return sum(map(mul, a, b))


def matvec(rows, x) -> list[float]:
    """A x for A given by its rows."""
    if len(x) == 3:
        x0, x1, x2 = x
        return [a0 * x0 + a1 * x1 + a2 * x2 for a0, a1, a2 in rows]
    return [sum(map(mul, row, x)) for row in rows]


def rows_of(matrix: np.ndarray) -> tuple[tuple[float, ...], ...]:
    """A 2-D array as a tuple of row tuples (its transpose: `rows_of(matrix.T)`)."""
    return tuple(map(tuple, np.asarray(matrix, dtype=float).tolist()))


def floats(vector) -> list[float]:
    """A 1-D array (or any sequence of numbers) as a list of Python floats."""
    if isinstance(vector, np.ndarray):
        return vector.astype(float, copy=False).tolist()
    return [float(value) for value in vector]


def all_finite(values) -> bool:
    """np.all(np.isfinite(values)) for a short sequence of floats."""
    for value in values:
        if value - value != 0.0:        # inf − inf and NaN − NaN are NaN
            return False
    return True
