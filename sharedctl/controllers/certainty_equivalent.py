"""Certainty-equivalent adaptive law (paper (12)).

    u_f = −K_p p − Kᵀ Z1 z + Y θ̂,      θ̂̇ = −(1/γ_θ) Yᵀ p,

with Y θ = M v̇_ref + C(q, v) v_ref + g. Along solutions, with θ̃ = θ̂ − θ,

    L = ½ (zᵀz + pᵀ M p + γ_θ θ̃ᵀθ̃),   L̇ = (λ_q + 1) zᵀ Z1 z − pᵀ K_p p ≤ 0,

since Z1 = diag(1/x) is negative definite inside the group. −Kᵀ Z1 z grows without bound
as a face is approached (z → −∞, 1/x → −∞), which is what makes this law keep the
group's rows negative from any initial state with finite L.

Robust form (adaptation.py, docs/control.md §11): θ̂̇ = −(1/γ_θ) Yᵀ p − σ₀ (θ̂ − P_T(θ̂)), which adds
−γ_θ σ₀ θ̃ᵀ(θ̂ − P_T(θ̂)) ≤ −γ_θ σ₀ |θ̂ − P_T(θ̂)|² to L̇ while θ lies in the trust box T (nothing
while θ̂ is in T).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ..short_vectors import dot, floats, matvec
from ..transform import reference_signals
from .adaptation import Adaptation, leaked
from .base import LawOutput, MachineLaw, cached_gain_floats, diag_gain


@dataclass
class CertaintyEquivalentLaw(MachineLaw):
    """(12). Gains: K_p (diagonal), λ_q, γ_θ; the robust update's σ₀ and boxes (`adaptation`)."""

    Kp: float | list[float] = 40.0
    lam: float = 1.5
    gamma_theta: float = 0.5
    adaptation: Adaptation = field(default_factory=Adaptation)
    name: str = field(default="ce", init=False)
    configuration: ClassVar[str] = "ce"

    def state_size(self, model) -> int:
        return 0

    def initial_state(self, model, group, c, q, v, theta_hat) -> np.ndarray:
        return np.zeros(0)

    def error_signals(self, model, group, c, q, v):
        """(p, ż, v_ref, v̇_ref) at one instant."""
        f = group.floats
        return tuple(map(np.array, reference_signals(c.floats, f.K, f.K_inv, floats(v), self.lam)))

    def evaluate(self, model, group, c, q, v, theta_hat, state) -> LawOutput:
        """(12) on Python floats (short_vectors); numpy arrays in and out."""
        f, cf, v = group.floats, c.floats, floats(v)
        p, _, v_ref, a_ref = reference_signals(cf, f.K, f.K_inv, v, self.lam)
        Y = model.regressor_rows(floats(q), v, v_ref, a_ref)
        kp, theta = cached_gain_floats(self, "Kp", model.n), floats(theta_hat)
        u = barrier_force(f, cf, kp, p, Y, theta)
        theta_dot = leaked([-dot(column, p) / self.gamma_theta for column in zip(*Y)],   # −Yᵀ p / γ_θ
                           self.adaptation.leak(model, theta))                             # − σ₀(θ̂ − P_T θ̂)
        return LawOutput(np.array(u), np.array(theta_dot), _NO_STATE)

    def lyapunov(self, model, group, c, q, v, theta_hat) -> float:
        """L of Theorem 1 with the true θ (for analysis and tests only: the law never sees θ)."""
        p, *_ = self.error_signals(model, group, c, q, v)
        err = theta_hat - model.theta
        return 0.5 * float(c.z @ c.z + p @ model.mass(q) @ p + self.gamma_theta * err @ err)

    def lyapunov_rate(self, model, group, c, q, v) -> float:
        """L̇ = (λ_q + 1) zᵀ Z1 z − pᵀ K_p p, the value the proof predicts (θ̂ in the trust box: no leakage)."""
        p, *_ = self.error_signals(model, group, c, q, v)
        kp = diag_gain(self.Kp, model.n)
        return float((self.lam + 1.0) * np.sum(c.z**2 / c.x) - p @ (kp * p))


def barrier_force(f, cf, kp, p, Y, theta) -> list:
    """u_f of (12) on floats: −K_p p − Kᵀ Z1 z + Y θ̂ (f: the group's float rows, cf: its coordinates)."""
    barrier = matvec(f.K_transposed, [zj / xj for zj, xj in zip(cf.z, cf.x)])         # Kᵀ Z1 z
    return [-kj * pj - bj + dot(row, theta) for kj, pj, bj, row in zip(kp, p, barrier, Y)]


_NO_STATE = np.zeros(0)
_NO_STATE.flags.writeable = False
