"""The paper's non-certainty-equivalent (immersion-and-invariance style) law, as printed ((13)–(15)).

Regressor W (14):  W θ = Ṁ s + k_q M p − C(q, v) p − Y θ,   s = p + (k_q − α_n) p_n.
Filters (14):      ṗ_n = −α_n p_n + p,      Ẇ_n = −α_n W_n + W.
Law (13):          β = γ_n W_nᵀ p_n,
                   u_f = −W (θ̂ + β) − γ_n W_n W_nᵀ s,
                   θ̂̇ = γ_n (α_n W_n − W)ᵀ p_n + γ_n k_q W_nᵀ p_n.
Initial state (15): p_n(0) = p(0)/(α_n − k_q), W_n(0) = 0 (α_n ≠ k_q).

For any input u, M s = W_n θ + u_n with u̇_n = −α_n u_n + u (composite_adaptive.py derives it);
θ̂̇ + β̇ = γ_n W_nᵀ s whatever u is. Only when u is exactly (13) is u_n = −W_n (θ̂ + β), and
only then, with θ̃ = θ̂ + β − θ, θ̃̇ = −γ_n W_nᵀ M⁻¹ W_n θ̃ (the paper's error dynamics); an added
term u_b adds γ_n W_nᵀ M⁻¹ u_{b,n}, with M unknown. The estimate this law stands for is θ̂ + β.

This law has no term that grows near a face, so it does not keep the state inside
(tests/test_non_certainty_equivalent.py shows a crossing from speed). No configuration runs
it: the NCE configuration runs CompositeAdaptiveLaw (composite_adaptive.py) on the same
filters, with (12)'s barrier (docs/control.md §4.2). It is kept as the paper's law, for the
tests that document why.

Robust form (adaptation.py, docs/control.md §11): θ̂̇ less σ₀ (ϑ − P_T(ϑ)) with ϑ = θ̂ + β the estimate
the law stands for, so that θ̃̇ gains −σ₀ (ϑ − P_T(ϑ)) and the θ̃ part of its Lyapunov function the
non-positive −σ₀ θ̃ᵀ(ϑ − P_T(ϑ)); θ̂ itself is never projected (`projects_estimate`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..short_vectors import dot, floats
from ..transform import reference_signals
from .adaptation import Adaptation, leaked
from .base import LawOutput, MachineLaw


def filtered_regressor_rows(model, q: list, v: list, p: list, s: list, Y: list, k_q: float) -> list:
    """W of (14) by rows, on floats: Y_Ṁ(q, v, s) + k_q Y_M(q, p) − Y_C(q, v, p) − Y, with
    Y = Y(q, v, v_ref, v̇_ref) the regressor of (11) already evaluated."""
    return [[mr + k_q * m - cr - y for mr, m, cr, y in zip(*rows)] for rows in zip(
        model.mass_rate_regressor_rows(q, v, s), model.mass_regressor_rows(q, p),
        model.coriolis_regressor_rows(q, v, p), Y)]


@dataclass
class NonCertaintyEquivalentLaw(MachineLaw):
    """(13)–(15) as printed. Gains: λ_q, k_q, α_n, γ_n (paper: γ_n ≥ 1/k_q)."""

    lam: float = 1.5
    k_q: float = 1.0
    alpha_n: float = 3.0
    gamma_n: float = 200.0
    adaptation: Adaptation = field(default_factory=Adaptation)
    name: str = field(default="nce13", init=False)
    projects_estimate: bool = field(default=False, init=False)

    def __post_init__(self):
        if abs(self.alpha_n - self.k_q) < 1e-9:
            raise ValueError("NCE needs alpha_n != k_q (initial condition (15))")
        if min(self.lam, self.k_q, self.alpha_n, self.gamma_n) <= 0:
            raise ValueError("NCE gains must be positive")

    def state_size(self, model) -> int:
        return model.n + model.n * model.n_theta

    def _p(self, group, c, v):
        f = group.floats
        p, _, v_ref, a_ref = reference_signals(c.floats, f.K, f.K_inv, floats(v), self.lam)
        return np.array(p), np.array(v_ref), np.array(a_ref)

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
        """(13)–(14) on Python floats (short_vectors); numpy arrays in and out. W, W_n by rows."""
        n, f, v = model.n, group.floats, floats(v)
        p_n, W_n = self._split_floats(n, len(theta_hat), floats(state))
        p, _, v_ref, a_ref = reference_signals(c.floats, f.K, f.K_inv, v, self.lam)
        kq, alpha, g = self.k_q, self.alpha_n, self.gamma_n
        s = [pj + (kq - alpha) * pnj for pj, pnj in zip(p, p_n)]
        q = floats(q)
        W = filtered_regressor_rows(model, q, v, p, s, model.regressor_rows(q, v, v_ref, a_ref), kq)
        W_n_columns = list(zip(*W_n))
        wp = [dot(column, p_n) for column in W_n_columns]                                 # W_nᵀ p_n
        estimate = [th + g * b for th, b in zip(floats(theta_hat), wp)]                    # θ̂ + β
        ws = [dot(column, s) for column in W_n_columns]                                   # W_nᵀ s
        u = [-dot(w, estimate) - g * dot(wn, ws) for w, wn in zip(W, W_n)]
        theta_dot = leaked([g * dot([alpha * a - b for a, b in zip(cn, cw)], p_n) + g * kq * wpj
                            for cn, cw, wpj in zip(W_n_columns, zip(*W), wp)],
                           self.adaptation.leak(model, estimate))                        # − σ₀(ϑ − P_T ϑ)
        p_n_dot = [-alpha * pnj + pj for pnj, pj in zip(p_n, p)]
        W_n_dot = [-alpha * a + b for wn, w in zip(W_n, W) for a, b in zip(wn, w)]
        return LawOutput(np.array(u), np.array(theta_dot), np.array(p_n_dot + W_n_dot))

    @staticmethod
    def _split_floats(n: int, n_theta: int, state: list) -> tuple[list, list]:
        """(p_n, rows of W_n) from the law's state as floats."""
        return state[:n], [state[n + i * n_theta:n + (i + 1) * n_theta] for i in range(n)]

    def estimate(self, theta_hat, state):
        """θ̂ + β, β = γ_n W_nᵀ p_n."""
        return theta_hat + self._beta(theta_hat.size, state)

    def _beta(self, n_theta: int, state: np.ndarray) -> np.ndarray:
        p_n, W_n = self._split_floats(state.size // (1 + n_theta), n_theta, state.tolist())
        return np.array([self.gamma_n * dot(column, p_n) for column in zip(*W_n)])
