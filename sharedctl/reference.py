"""The projected feasible reference x_r (paper (7)) and its time derivatives.

For each row j of a group, m = k_j q_d + t_j is the constraint value at the
operator's desired configuration. The printed two-branch formula (7) lost its signs;
what the proofs need is a smooth, strictly negative x_r(m) with x_r ≈ m when m ≪ −ε.
We use the softplus saturation

    x_r(m) = −ε − (1/γ) ln(1 + exp(−γ (m + ε))),

which is C^∞, satisfies x_r < −ε for every m (≤ in floating point far outside), x_r → m as m → −∞ and x_r → −ε as m → +∞
(q_d on or beyond the face). Its derivatives are σ′(m) = s and σ″(m) = −γ s (1 − s)
with s = 1/(1 + exp(γ (m + ε))), so ẋ_r = σ' ṁ and ẍ_r = σ'' ṁ² + σ' m̈ with
ṁ = k_j q̇_d and m̈ = k_j q̈_d. See docs/control.md §3.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ReferenceShape:
    """ε (m): the closest the reference comes to a face; γ (1/m): sharpness of the bend."""

    epsilon: float = 0.05
    gamma: float = 40.0

    def __post_init__(self):
        if not (self.epsilon > 0 and self.gamma > 0):
            raise ValueError("reference epsilon and gamma must be positive")


def saturate(m: np.ndarray, shape: ReferenceShape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """x_r = σ(m), σ'(m), σ''(m), elementwise and overflow-free."""
    eps, g = shape.epsilon, shape.gamma
    u = -g * (m + eps)
    x_r = -eps - np.logaddexp(0.0, u) / g      # ln(1 + e^u), overflow-free
    s = 0.5 + 0.5 * np.tanh(0.5 * u)           # = 1/(1+e^{-u}) = 1/(1+exp(γ(m+ε)))
    return x_r, s, -g * s * (1.0 - s)


def saturate_floats(m: list, shape: ReferenceShape) -> tuple[list, list, list]:
    """`saturate` on a short list of Python floats: the same formulas term by term, np.logaddexp's
    branches written out (ln(1 + e^u) = u + ln(1 + e^−u) for u > 0, ln(1 + e^u) for u < 0).
    tanh is numpy's own: far inside a face 1 − s keeps only a few digits, so σ'' = −γ s (1 − s)
    depends on tanh's last bit, and it must be the bit the vectorised `saturate` gets."""
    eps, g = shape.epsilon, shape.gamma
    u = [-g * (mj + eps) for mj in m]
    x_r, s, d2 = [], [], []
    for uj, tj in zip(u, np.tanh([0.5 * uj for uj in u]).tolist()):
        if uj > 0.0:
            softplus = uj + math.log1p(math.exp(-uj))
        elif uj < 0.0:
            softplus = math.log1p(math.exp(uj))
        else:
            softplus = _LN2 if uj == 0.0 else uj        # uj NaN: NaN
        sj = 0.5 + 0.5 * tj
        x_r.append(-eps - softplus / g)
        s.append(sj)
        d2.append(-g * sj * (1.0 - sj))
    return x_r, s, d2


_LN2 = math.log(2.0)


def projected_reference(
    K: np.ndarray, T: np.ndarray, q_d: np.ndarray, qd_dot: np.ndarray, qd_ddot: np.ndarray, shape: ReferenceShape
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x_r, ẋ_r, ẍ_r) for one group's rows K, T."""
    m = K @ q_d + T
    m_dot = K @ qd_dot
    m_ddot = K @ qd_ddot
    x_r, d1, d2 = saturate(m, shape)
    return x_r, d1 * m_dot, d2 * m_dot**2 + d1 * m_ddot
