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
(29) less σ₀ (θ̂ − P_T(θ̂)) is its robust form (adaptation.py, §11): −γ_θ σ₀ θ̃ᵀ(θ̂ − P_T(θ̂)) ≤ 0 more
in the rate of that function.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ..short_vectors import dot, floats, matvec
from .adaptation import Adaptation, leaked
from .base import LawOutput, MachineLaw, cached_gain_floats
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
    adaptation: Adaptation = field(default_factory=Adaptation)
    name: str = field(default="of", init=False)
    configuration: ClassVar[str] = "of"

    def state_size(self, model) -> int:
        return 2 * model.n

    def initial_state(self, model, group, c, q, v, theta_hat) -> np.ndarray:
        return np.concatenate([np.zeros(model.n), (self.k2 + 1.0) * c.z])

    def evaluate(self, model, group, c, q, v_hat, theta_hat, state) -> LawOutput:
        """(25)–(29) on Python floats (short_vectors); numpy arrays in and out."""
        n, f, cf = model.n, group.floats, c.floats
        state = floats(state)
        z_f, xi, z, x = state[:n], state[n:], cf.z, cf.x
        k = self.k2 + 1.0
        r_f = [xij - k * zj for xij, zj in zip(xi, z)]
        ez = [math.exp(zj) for zj in z]
        w = matvec(f.K_inv, [e * d for e, d in zip(ez, cf.x_r_dot)])
        w0_dot = matvec(f.K_inv, [e * dd for e, dd in zip(ez, cf.x_r_ddot)])        # ẇ₀
        Psi = model.regressor_rows(floats(q), w, w, w0_dot)
        k1 = cached_gain_floats(self, "K1", n)
        sign = smooth_sign(np.array([zj + zfj for zj, zfj in zip(z, z_f)]), self.sign_width).tolist()
        inner = [-k1j * sj + k * rj - zj for k1j, sj, rj, zj in zip(k1, sign, r_f, z)]
        pushed = matvec(f.K_transposed, [self.stiffness * ij / xj for ij, xj in zip(inner, x)])
        theta = floats(theta_hat)
        u = [pj + dot(row, theta) for pj, row in zip(pushed, Psi)]
        z_f_dot = [-zfj + rj for zfj, rj in zip(z_f, r_f)]
        xi_dot = [-rj - k * (zj + rj) + zj - zfj for rj, zj, zfj in zip(r_f, z, z_f)]
        zd_hat = [kv / xj - d / xr for kv, xj, d, xr in zip(matvec(f.K, floats(v_hat)), x, cf.x_r_dot, cf.x_r)]
        eta_hat = [zdj + zj + rj for zdj, zj, rj in zip(zd_hat, z, r_f)]
        n_eta = matvec(f.K_inv, [xj * ej for xj, ej in zip(x, eta_hat)])                # N η̂
        theta_dot = leaked([-dot(column, n_eta) / self.gamma_theta for column in zip(*Psi)],
                           self.adaptation.leak(model, theta))
        return LawOutput(np.array(u), np.array(theta_dot), np.array(z_f_dot + xi_dot))
