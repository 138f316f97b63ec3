"""Non-certainty-equivalent (immersion-and-invariance style) adaptive law (paper (13)–(15)).

Regressor W (14):  W θ = Ṁ s + k_q M p − C(q, v) p − Y θ,   s = p + (k_q − α_n) p_n.
Filters (14):      ṗ_n = −α_n p_n + p,      Ẇ_n = −α_n W_n + W.
Law (13):          β = γ_n W_nᵀ p_n,
                   u_f = −W (θ̂ + β) − γ_n W_n W_nᵀ s,
                   θ̂̇ = γ_n (α_n W_n − W)ᵀ p_n + γ_n k_q W_nᵀ p_n.
Initial state (15): p_n(0) = p(0)/(α_n − k_q), W_n(0) = 0 (α_n ≠ k_q).

With these, M (ṗ_n + k_q p_n) = W_n θ + u_n and u_n = −W_n (θ̂ + β) hold for all time,
so with θ̃ = θ̂ + β − θ:  ṗ_n = −k_q p_n − M⁻¹ W_n θ̃ and θ̃̇ = −γ_n W_nᵀ M⁻¹ W_n θ̃.
The estimate this law stands for is θ̂ + β.

This law has no term that grows near a face, so on its own it does not keep the state
inside (docs/control.md §4.2 and tests/test_non_certainty_equivalent.py show a crossing). The sharing
arbiter therefore never applies it in the hazardous set: there the certainty-equivalent
law (12) takes over, seeded with θ̂ + β.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..transform import reference_velocity_acceleration, z_dot
from .base import LawOutput, MachineLaw


@dataclass
class NonCertaintyEquivalentLaw(MachineLaw):
    """(13)–(15). Gains: λ_q, k_q, α_n, γ_n (paper: γ_n ≥ 1/k_q)."""

    lam: float = 1.5
    k_q: float = 1.0
    alpha_n: float = 3.0
    gamma_n: float = 200.0
    name: str = field(default="nce", init=False)
    projects_estimate: bool = field(default=False, init=False)

    def __post_init__(self):
        if abs(self.alpha_n - self.k_q) < 1e-9:
            raise ValueError("NCE needs alpha_n != k_q (initial condition (15))")
        if min(self.lam, self.k_q, self.alpha_n, self.gamma_n) <= 0:
            raise ValueError("NCE gains must be positive")

    def state_size(self, model) -> int:
        return model.n + model.n * model.n_theta

    def _split(self, model, state):
        n, k = model.n, model.n_theta
        return state[:n], state[n:].reshape(n, k)

    def _p(self, group, c, v):
        zd = z_dot(c, group.K @ v)
        v_ref, a_ref = reference_velocity_acceleration(group, c, zd, self.lam)
        return v - v_ref, v_ref, a_ref

    def initial_state(self, model, group, c, q, v, theta_hat) -> np.ndarray:
        p, _, _ = self._p(group, c, v)
        p_n = p / (self.alpha_n - self.k_q)
        return np.concatenate([p_n, np.zeros(model.n * model.n_theta)])

    def regressor_w(self, model, q, v, p, p_n, v_ref, a_ref) -> np.ndarray:
        """W of (14)."""
        s = p + (self.k_q - self.alpha_n) * p_n
        return (
            model.mass_rate_regressor(q, v, s)
            + self.k_q * model.mass_regressor(q, p)
            - model.coriolis_regressor(q, v, p)
            - model.regressor(q, v, v_ref, a_ref)
        )

    def evaluate(self, model, group, c, q, v, theta_hat, state) -> LawOutput:
        p_n, W_n = self._split(model, state)
        p, v_ref, a_ref = self._p(group, c, v)
        W = self.regressor_w(model, q, v, p, p_n, v_ref, a_ref)
        s = p + (self.k_q - self.alpha_n) * p_n
        g = self.gamma_n
        beta = g * (W_n.T @ p_n)
        u = -W @ (theta_hat + beta) - g * (W_n @ (W_n.T @ s))
        theta_dot = g * ((self.alpha_n * W_n - W).T @ p_n) + g * self.k_q * (W_n.T @ p_n)
        p_n_dot = -self.alpha_n * p_n + p
        W_n_dot = -self.alpha_n * W_n + W
        return LawOutput(u, theta_dot, np.concatenate([p_n_dot, W_n_dot.ravel()]))

    def estimate(self, theta_hat, state):
        """θ̂ + β, β = γ_n W_nᵀ p_n."""
        return theta_hat + self._beta(theta_hat.size, state)

    def _beta(self, n_theta: int, state: np.ndarray) -> np.ndarray:
        n = state.size // (1 + n_theta)
        p_n, W_n = state[:n], state[n:].reshape(n, n_theta)
        return self.gamma_n * (W_n.T @ p_n)
