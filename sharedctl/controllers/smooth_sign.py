"""The smooth sign used in place of sgn(·) in (25) and (40): tanh(s/φ).

A discrete-time sgn chatters at the sample rate; tanh(s/φ) equals sgn(s) to within
e^{-2|s|/φ} once |s| ≫ φ and is Lipschitz with constant 1/φ, so RK4 integrates it.
The price is an ultimate bound of order φ on the signals it acts on instead of exact
convergence (docs/control.md §4.4).
"""
from __future__ import annotations

import numpy as np


def smooth_sign(s: np.ndarray, width: float) -> np.ndarray:
    return np.tanh(np.asarray(s) / width)
