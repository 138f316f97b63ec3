"""The NCE configuration's law: (12) with a composite update on the filters (14)–(15).

Filters (the paper's (14)–(15), and one more of the applied input), s = p + (k_q − α_n) p_n:

    ṗ_n = −α_n p_n + p,   Ẇ_n = −α_n W_n + W,   u̇_n = −α_n u_n + u_s,
    W θ = Ṁ s + k_q M p − C(q, v) p − Y θ,
    p_n(0) = p(0)/(α_n − k_q),  W_n(0) = 0,  u_n(0) = 0,

with u_s the input the plant receives ((46)/(47)), whatever it is. With M ṗ = u_s − C p − Y θ,
e = M s − W_n θ − u_n obeys ė = −α_n e, and e(0) = 0, so M s = W_n θ + u_n at all times. Since
M s = Y_M(q, s) θ, this is a linear regression with measured signals:

    Φ θ = u_n,   Φ = Y_M(q, s) − W_n.

Law (ours): the barrier controller of (12), with a composite update (tracking error and
prediction error, Slotine & Li's composite adaptation), projected onto the model's box:

    u_f = −K_p p − Kᵀ Z1 z + Y θ̂,
    θ̂̇ = −(1/γ_θ) Yᵀ p − γ_n Φᵀ (Φ θ̂ − u_n) / (1 + ν |Φ|²).

With θ̃ = θ̂ − θ (so Φ θ̂ − u_n = Φ θ̃) and L = ½ (zᵀz + pᵀ M p + γ_θ θ̃ᵀθ̃):

    L̇ = (λ_q + 1) zᵀ Z1 z − pᵀ K_p p − γ_θ γ_n |Φ θ̃|² / (1 + ν |Φ|²) ≤ 0,

so §4.1's margin ε·e^{−√(2 L(0))} holds, and the normalised prediction error is square
integrable. The normalisation bounds the update's stiffness by γ_n/ν (|Φ|² ≥ λ_max(ΦᵀΦ)),
which keeps the 500 Hz Euler step of θ̂ stable near a face, where Φ grows like 1/x².
docs/control.md §4.2. The update less σ₀ (θ̂ − P_T(θ̂)) is its robust form (adaptation.py, §11):
one more term −γ_θ σ₀ θ̃ᵀ(θ̂ − P_T(θ̂)) ≤ 0 in L̇.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ..short_vectors import dot, floats
from ..transform import reference_signals
from .adaptation import Adaptation, leaked
from .base import LawOutput, MachineLaw, cached_gain_floats
from .certainty_equivalent import CertaintyEquivalentLaw, barrier_force
from .non_certainty_equivalent import filtered_regressor_rows


@dataclass
class CompositeAdaptiveLaw(MachineLaw):
    """(12) with the composite update on (14)–(15)'s filters. Gains: K_p, λ_q, γ_θ (as (12));
    k_q, α_n (the filters); γ_n, ν (the prediction-error term)."""

    Kp: float | list[float] = 40.0
    lam: float = 1.5
    gamma_theta: float = 0.5
    k_q: float = 1.0
    alpha_n: float = 3.0
    gamma_n: float = 30.0
    nu: float = 1.0
    adaptation: Adaptation = field(default_factory=Adaptation)
    name: str = field(default="nce", init=False)
    configuration: ClassVar[str] = "nce"

    def __post_init__(self):
        if abs(self.alpha_n - self.k_q) < 1e-9:
            raise ValueError("the composite law needs alpha_n != k_q (initial condition (15))")
        if min(self.lam, self.gamma_theta, self.k_q, self.alpha_n, self.gamma_n) <= 0 or self.nu < 0:
            raise ValueError("composite-law gains must be positive (nu >= 0)")

    def state_size(self, model) -> int:
        """[p_n (n), W_n (n·n_θ, by rows), u_n (n)]."""
        return 2 * model.n + model.n * model.n_theta

    def initial_state(self, model, group, c, q, v, theta_hat) -> np.ndarray:
        """(15): p_n(0) = p(0)/(α_n − k_q), W_n(0) = 0; and u_n(0) = 0."""
        f = group.floats
        p, *_ = reference_signals(c.floats, f.K, f.K_inv, floats(v), self.lam)
        n, k = model.n, model.n_theta
        return np.concatenate([np.array(p) / (self.alpha_n - self.k_q), np.zeros(n * k + n)])

    def evaluate(self, model, group, c, q, v, theta_hat, state) -> LawOutput:
        """u_f, θ̂̇ and the filters' rate without u_s (`with_applied_input` adds it), on floats."""
        n, f, cf, v = model.n, group.floats, c.floats, floats(v)
        k = len(theta_hat)
        state = floats(state)
        p_n, W_n, u_n = split(n, k, state)
        p, _, v_ref, a_ref = reference_signals(cf, f.K, f.K_inv, v, self.lam)
        q, theta = floats(q), floats(theta_hat)
        Y = model.regressor_rows(q, v, v_ref, a_ref)
        kp, kq, alpha = cached_gain_floats(self, "Kp", n), self.k_q, self.alpha_n
        u = barrier_force(f, cf, kp, p, Y, theta)                                       # (12)
        s = [pj + (kq - alpha) * pnj for pj, pnj in zip(p, p_n)]
        W = filtered_regressor_rows(model, q, v, p, s, Y, kq)
        Phi = [[m - w for m, w in zip(mr, wr)] for mr, wr in zip(model.mass_regressor_rows(q, s), W_n)]
        error = [dot(row, theta) - un for row, un in zip(Phi, u_n)]                    # Φ θ̂ − u_n
        gain = self.gamma_n / (1.0 + self.nu * sum(dot(row, row) for row in Phi))
        theta_dot = leaked([-dot(cy, p) / self.gamma_theta - gain * dot(cp, error)
                            for cy, cp in zip(zip(*Y), zip(*Phi))], self.adaptation.leak(model, theta))
        rate = ([-alpha * a + b for a, b in zip(p_n, p)]
                + [-alpha * a + b for wn, w in zip(W_n, W) for a, b in zip(wn, w)]
                + [-alpha * a for a in u_n])
        return LawOutput(np.array(u), np.array(theta_dot), np.array(rate))

    def with_applied_input(self, state_dot: np.ndarray, u_applied: np.ndarray) -> np.ndarray:
        """u̇_n = −α_n u_n + u_s: adds u_s to the last n entries of `evaluate`'s rate."""
        n = len(u_applied)
        out = state_dot.copy()
        out[-n:] += u_applied
        return out

    def lyapunov(self, model, group, c, q, v, theta_hat) -> float:
        """L = ½(zᵀz + pᵀMp + γ_θ|θ̃|²) with the true θ, (12)'s (for analysis and tests only)."""
        return CertaintyEquivalentLaw.lyapunov(self, model, group, c, q, v, theta_hat)

    def error_signals(self, model, group, c, q, v):
        """(p, ż, v_ref, v̇_ref) at one instant, (12)'s."""
        return CertaintyEquivalentLaw.error_signals(self, model, group, c, q, v)


def split(n: int, n_theta: int, state: list) -> tuple[list, list, list]:
    """(p_n, rows of W_n, u_n) from the composite law's state as floats."""
    end = n + n * n_theta
    return state[:n], [state[n + i * n_theta:n + (i + 1) * n_theta] for i in range(n)], state[end:end + n]
