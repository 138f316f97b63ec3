"""Adaptive output-feedback law (paper (25)–(29)), RISE-like, no velocity in the loop.

With N = K⁻¹ Z1⁻¹ = K⁻¹ diag(x) (so v = N ż + w, w = K⁻¹ (e^z ∘ ẋ_r)), the plant reads
M N z̈ + f_a + Ψ θ = u (24), where Ψ θ = M ẇ₀ + C(q, w) w + g collects what does not
depend on ż (ẇ₀ = K⁻¹ (e^z ∘ ẍ_r)): Ψ is computable from q and the reference alone.

    u_f = k_o Kᵀ Z1 [−K1 sgn(z + z_f) + (k2 + 1) r_f − z] + Ψ θ̂    (25)
    ż_f = −z_f + r_f,                      z_f(0) = 0               (26)
    r_f = ξ − (k2 + 1) z                                            (27)
    ξ̇ = −r_f − (k2 + 1)(z + r_f) + z − z_f, ξ(0) = (k2 + 1) z(0)    (28)
    θ̂̇ = −(1/γ_θ) Ψᵀ N η̂,   η̂ = ż̂ + z + r_f                        (29)

With η = ż + z + r_f, (26)–(28) give ṙ_f = −r_f − (k2+1) η + z − z_f, and the function
½(k_o(|z|² + |z_f|² + |r_f|²) + (Nη)ᵀ M (Nη) + γ_θ |θ̃|²) loses every cross term between
z, z_f, r_f and η (the paper has k_o = 1; a scalar k_o > 0 scales the law to the plant's
inertia without touching the cancellation); the printed (29) is dimensionally garbled, and the cross term it must
cancel is θ̃ᵀ Ψᵀ N η, which contains ż: we use the observer's ż̂ (40) for it (separation,
as the paper invokes for (38)). sgn is the smooth sign tanh(·/φ). docs/control.md §4.4.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .base import LawOutput, MachineLaw, cached_gain
from .smooth_sign import smooth_sign


@dataclass
class OutputFeedbackLaw(MachineLaw):
    """(25)–(29). Gains: K1 (diagonal), k2, γ_θ, sign width φ."""

    K1: float | list[float] = 0.5
    k2: float = 8.0
    stiffness: float = 30.0  # k_o (N): weights the z, z_f, r_f part of the Lyapunov function
    gamma_theta: float = 0.1
    sign_width: float = 0.05
    lam: float = 1.0      # only for the selection Lyapunov value in sharing.py
    name: str = field(default="of", init=False)

    def state_size(self, model) -> int:
        return 2 * model.n

    def initial_state(self, model, group, c, q, v, theta_hat) -> np.ndarray:
        return np.concatenate([np.zeros(model.n), (self.k2 + 1.0) * c.z])

    def evaluate(self, model, group, c, q, v_hat, theta_hat, state) -> LawOutput:
        n = model.n
        z_f, xi = state[:n], state[n:]
        z = c.z
        k = self.k2 + 1.0
        r_f = xi - k * z
        ez = np.exp(z)
        both = group.K_inv @ np.array([ez * c.x_r_dot, ez * c.x_r_ddot]).T     # w, ẇ₀ in one product
        w, w0_dot = both[:, 0], both[:, 1]
        Psi = model.regressor(q, w, w, w0_dot)
        k1 = cached_gain(self, "K1", n)
        inner = -k1 * smooth_sign(z + z_f, self.sign_width) + k * r_f - z
        u = group.K.T @ (self.stiffness * inner / c.x) + Psi @ theta_hat
        z_f_dot = -z_f + r_f
        xi_dot = -r_f - k * (z + r_f) + z - z_f
        zd_hat = (group.K @ v_hat) / c.x - c.x_r_dot / c.x_r
        eta_hat = zd_hat + z + r_f
        theta_dot = -(Psi.T @ (group.K_inv @ (c.x * eta_hat))) / self.gamma_theta
        return LawOutput(u, theta_dot, np.concatenate([z_f_dot, xi_dot]))
