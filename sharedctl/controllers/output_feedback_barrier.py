"""The output-feedback configuration's law for the hazardous set: a barrier law on the observer's v̂
whose velocity-dependent gains stay bounded near a face (docs/control.md §4.3).

Same z = ln(x/x_r), p = v − v_ref and L = ½(zᵀz + pᵀMp + γ_θ|θ̃|²) as (12), but with the
reference velocity of transform.bounded_reference_signals,

    v_ref = K⁻¹[e^z ∘ ẋ_r + x ∘ μ(z)],   μ(z) = −λ tanh z,   ż = Z1 K p + μ(z),

whose rate v̇_ref multiplies ẋ by ẋ_r/x_r + μ + μ′ (bounded) where (12)'s multiplies it by
(1 + λ)/x. On the observer (p̂ = v̂ − v_ref, v̇̂_ref with ẋ̂ = K v̂, Ŷ = Y(q, v̂, v_ref, v̇̂_ref)):

    u_f = −K_p p̂ − Kᵀ Z1 z + Ŷ θ̂,      θ̂̇ = −(1/γ_θ) Ŷᵀ p̂,

θ̂ projected onto the model's box after each step. With ṽ = v − v̂ = 0,
L̇ = −λ Σ z_j tanh z_j − pᵀ K_p p ≤ 0; with ṽ ≠ 0 the residual is linear in ṽ with gains bounded
on the set, which gives the input-to-state safety bound of docs/control.md §4.3. The update less
σ₀ (θ̂ − P_T(θ̂)) is its robust form (adaptation.py, §11): −γ_θ σ₀ θ̃ᵀ(θ̂ − P_T(θ̂)) ≤ 0 more in L̇.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ..short_vectors import dot, floats, matvec
from ..transform import bounded_reference_signals
from .adaptation import Adaptation, leaked
from .base import LawOutput, MachineLaw, cached_gain_floats, diag_gain

_NO_STATE = np.zeros(0)


@dataclass
class OutputFeedbackBarrierLaw(MachineLaw):
    """The OF configuration's hazard law (§4.3). Gains: K_p (diagonal), λ (rate of μ), γ_θ, k_b.

    Defaults are the omnidirectional robot's: with a bounded velocity gain the braking near a face
    comes from K_p (damping, N·s/m) and the barrier, so K_p is 15 times (12)'s."""

    Kp: float | list[float] = 600.0
    lam: float = 1.5
    gamma_theta: float = 0.5
    barrier_weight: float = 10.0       # k_b: extra weight of z² on the face side (z < 0) in L (N·m)
    adaptation: Adaptation = field(default_factory=Adaptation)
    name: str = field(default="of-barrier", init=False)
    configuration: ClassVar[str] = "of"

    def __post_init__(self):
        if not (self.lam > 0.0 and self.gamma_theta > 0.0 and self.barrier_weight >= 0.0):
            raise ValueError("the output-feedback barrier law needs λ > 0, γ_θ > 0 and k_b ≥ 0")

    def state_size(self, model) -> int:
        return 0

    def initial_state(self, model, group, c, q, v, theta_hat) -> np.ndarray:
        return np.zeros(0)

    def error_signals(self, model, group, c, q, v):
        """(p, ż, v_ref, v̇_ref) at one instant for velocity v, as numpy arrays."""
        f = group.floats
        return tuple(map(np.array, bounded_reference_signals(c.floats, f.K, f.K_inv, floats(v), self.lam)))

    def evaluate(self, model, group, c, q, v_hat, theta_hat, state) -> LawOutput:
        """u_f and θ̂̇ on the observer's v̂, on Python floats (short_vectors)."""
        f, cf, v_hat = group.floats, c.floats, floats(v_hat)
        p_hat, _, v_ref, a_ref = bounded_reference_signals(cf, f.K, f.K_inv, v_hat, self.lam)
        Y = model.regressor_rows(floats(q), v_hat, v_ref, a_ref)
        kp, theta = cached_gain_floats(self, "Kp", model.n), floats(theta_hat)
        barrier = matvec(f.K_transposed, [wj / xj for wj, xj in zip(self.potential_slope(cf.z), cf.x)])  # Kᵀ Z1 V′(z)
        u = [-kj * pj - bj + dot(row, theta) for kj, pj, bj, row in zip(kp, p_hat, barrier, Y)]
        theta_dot = leaked([-dot(column, p_hat) / self.gamma_theta for column in zip(*Y)],   # −Ŷᵀ p̂ / γ_θ
                           self.adaptation.leak(model, theta))
        return LawOutput(np.array(u), np.array(theta_dot), _NO_STATE)

    def potential_slope(self, z: list) -> list:
        """V′(z) = z + k_b min(z, 0), elementwise, on floats."""
        kb = self.barrier_weight
        return [zj + kb * zj if zj < 0.0 else zj for zj in z]

    def lyapunov(self, model, group, c, q, v, theta_hat) -> float:
        """L = ½(zᵀz + pᵀMp + γ_θ|θ̃|²) with the true θ and velocity (analysis and tests only)."""
        p, *_ = self.error_signals(model, group, c, q, v)
        err = theta_hat - model.theta
        potential = c.z @ c.z + self.barrier_weight * np.sum(np.minimum(c.z, 0.0) ** 2)           # 2 Σ V(z_j)
        return 0.5 * float(potential + p @ model.mass(q) @ p + self.gamma_theta * err @ err)

    def lyapunov_rate(self, model, group, c, q, v) -> float:
        """L̇ = −λ Σ z_j tanh z_j − pᵀ K_p p, the value the proof predicts when v̂ = v."""
        p, *_ = self.error_signals(model, group, c, q, v)
        kp = diag_gain(self.Kp, model.n)
        slope = c.z + self.barrier_weight * np.minimum(c.z, 0.0)
        return float(-self.lam * np.sum(slope * np.tanh(c.z)) - p @ (kp * p))

    def lyapunov_residual(self, model, group, c, q, v, v_hat, theta_hat) -> float:
        """L̇ − (−λ Σ z tanh z − pᵀK_p p) when the law runs on v̂ ≠ v:
        pᵀ[K_p ṽ + (Ŷ − Y) θ] + ṽᵀ Ŷ θ̃ (= pᵀδ + θ̃ᵀ(Yᵀp − Ŷᵀp̂), δ = K_p ṽ + (Ŷ − Y) θ̂)."""
        p, _, v_ref, a_ref = self.error_signals(model, group, c, q, v)
        _, _, _, a_hat = self.error_signals(model, group, c, q, v_hat)
        Y = model.regressor(q, v, v_ref, a_ref)
        Y_hat = model.regressor(q, v_hat, v_ref, a_hat)
        v_tilde, theta = v - v_hat, model.theta
        kp = diag_gain(self.Kp, model.n)
        return float(p @ (kp * v_tilde + (Y_hat - Y) @ theta) + v_tilde @ Y_hat @ (theta_hat - theta))


#: max over s ≥ 0 of s(1 − tanh s) = 2s/(e^{2s} + 1), reached where (2s − 1)e^{2s} = 1: it equals
#: the Lambert W(1/e) = 0.27846…, rounded up, so that z tanh z ≥ |z| − KAPPA for every z
KAPPA = 0.2785
