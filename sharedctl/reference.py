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


def projected_reference(
    K: np.ndarray, T: np.ndarray, q_d: np.ndarray, qd_dot: np.ndarray, qd_ddot: np.ndarray, shape: ReferenceShape
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x_r, ẋ_r, ẍ_r) for one group's rows K, T."""
    m = K @ q_d + T
    m_dot = K @ qd_dot
    m_ddot = K @ qd_ddot
    x_r, d1, d2 = saturate(m, shape)
    return x_r, d1 * m_dot, d2 * m_dot**2 + d1 * m_ddot
