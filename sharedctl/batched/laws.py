"""The machine laws of sharedctl/controllers/ for a batch of robots, each on its own group.

Every function takes the robots' own group matrices gathered per robot — K, T, K⁻¹ of shape
(n, n, M) / (n, M) — and component-major signals (n, M), and returns what the scalar law's
`evaluate` returns: u_f, θ̂̇ and the law state's rate. The formulas (and their order of
operations) are those of the scalar laws:

* (12) certainty equivalent: u_f = −K_p p − Kᵀ(z/x) + Y θ̂, θ̂̇ = −Yᵀp/γ_θ;
* the composite law of the NCE configuration ((12) + prediction error on (14)–(15)'s filters),
  state [p_n, W_n, u_n];
* (25)–(29) output feedback, state [z_f, ξ];
* the output-feedback configuration's barrier law on v̂ (docs/control.md §4.3), no state;
* (40) the velocity observer on q, state [q̂, β_o].

Every law's θ̂̇ ends with the robust update's leakage −σ₀ (θ̂ − P_T(θ̂)) and the step projects θ̂ onto
the physical box B (`RobustUpdate`, controllers/adaptation.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..controllers import (
    CertaintyEquivalentLaw,
    CompositeAdaptiveLaw,
    OutputFeedbackBarrierLaw,
    OutputFeedbackLaw,
    VelocityObserver,
)
from ..controllers.base import diag_gain
from ..models import OmniRobot
from . import plant
from .geometry import saturate


def matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A x per robot: A (i, j, M), x (j, M) → (i, M)."""
    return np.einsum("ijm,jm->im", A, x)


def rmatvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Aᵀ x per robot: A (i, j, M), x (i, M) → (j, M)."""
    return np.einsum("ijm,im->jm", A, x)


def gather(a: np.ndarray, cols) -> np.ndarray:
    """a[..., cols] for an index array (`np.take`, several times faster than fancy indexing on
    a 2-D array); `a` itself when `cols` is None (every robot)."""
    return a if cols is None else a.take(cols, axis=-1)


def scatter(dst: np.ndarray, cols, src: np.ndarray) -> None:
    """dst[:, cols] = src, one row at a time (a 1-D assignment is several times faster)."""
    if cols is None:
        dst[...] = src
        return
    for i in range(dst.shape[0]):
        dst[i][cols] = src[i]


@dataclass(frozen=True)
class GroupFrame:
    """The active group of each robot: K, T, K⁻¹ (n, n, M) / (n, M)."""

    K: np.ndarray
    T: np.ndarray
    K_inv: np.ndarray

    @staticmethod
    def of(K_cols: np.ndarray, T_cols: np.ndarray, K_inv_cols: np.ndarray, group: np.ndarray) -> "GroupFrame":
        """Each robot's group matrices gathered from the tables (…, G) by its group index (M,)."""
        return GroupFrame(K_cols.take(group, axis=-1), T_cols.take(group, axis=-1), K_inv_cols.take(group, axis=-1))

    def take(self, index) -> "GroupFrame":
        return GroupFrame(self.K[..., index], self.T[..., index], self.K_inv[..., index])


@dataclass(frozen=True)
class Reference:
    """(x_r, ẋ_r, ẍ_r) of (7) for each robot's group at one instant (depends on the wish only),
    and ẋ_r/x_r (the reference's part of ż, (9))."""

    x_r: np.ndarray
    x_r_dot: np.ndarray
    x_r_ddot: np.ndarray
    rate: np.ndarray

    def take(self, index) -> "Reference":
        return Reference(self.x_r[:, index], self.x_r_dot[:, index], self.x_r_ddot[:, index], self.rate[:, index])


def projected_reference(frame: GroupFrame, qd, qd_dot, qd_ddot, shape) -> Reference:
    """reference.projected_reference for each robot's group."""
    m = matvec(frame.K, qd)
    m += frame.T
    m_dot = matvec(frame.K, qd_dot)
    m_ddot = matvec(frame.K, qd_ddot)
    x_r, d1, d2 = saturate(m, shape)
    # ẍ_r = σ'' ṁ² + σ' m̈, ẋ_r = σ' ṁ
    m_ddot *= d1
    d2 *= np.square(m_dot)
    d2 += m_ddot
    m_dot *= d1
    return Reference(x_r, m_dot, d2, np.divide(m_dot, x_r))


@dataclass(frozen=True)
class Coordinates:
    """transform.coordinates (the parts the laws read) for each robot."""

    x: np.ndarray
    z: np.ndarray
    ref: Reference

    @property
    def inside(self) -> np.ndarray:
        """x < 0 on every row of the group (False where x is NaN)."""
        x = self.x
        inside = x[0] < 0.0
        for row in x[1:]:
            inside &= row < 0.0
        return inside


def coordinates(frame: GroupFrame, q: np.ndarray, ref: Reference) -> Coordinates:
    x = matvec(frame.K, q)
    x += frame.T
    z = np.divide(x, ref.x_r)
    return Coordinates(x, np.log(z, out=z), ref)


def _error_signals(frame: GroupFrame, c: Coordinates, v, lam):
    """(p, v_ref, v̇_ref) of transform.py: v_ref = K⁻¹[(1+λ)z + e^z ẋ_r], p = v − v_ref,
    v̇_ref = K⁻¹[(1+λ)ż + e^z ż ẋ_r + e^z ẍ_r], ż = K v / x − ẋ_r/x_r (in-place, the same order)."""
    r = c.ref
    zd = matvec(frame.K, v)
    zd /= c.x
    zd -= r.rate
    ez = np.exp(c.z)
    w = np.multiply(ez, r.x_r_dot)
    w += (1.0 + lam) * c.z
    v_ref = matvec(frame.K_inv, w)
    np.multiply(ez, zd, out=w)
    w *= r.x_r_dot
    w += (1.0 + lam) * zd
    ez *= r.x_r_ddot
    w += ez
    a_ref = matvec(frame.K_inv, w)
    return np.subtract(v, v_ref, out=w), v_ref, a_ref


def _bounded_error_signals(frame: GroupFrame, c: Coordinates, v, lam):
    """(p, v_ref, v̇_ref) of transform.bounded_reference_signals: μ = −λ tanh z,
    v_ref = K⁻¹[x (ẋ_r/x_r + μ)], v̇_ref = K⁻¹[ẋ (ẋ_r/x_r + μ + μ′) − x (ẋ_r/x_r)(ẋ_r/x_r + μ′) + e^z ẍ_r],
    ẋ = K v, p = v − v_ref (the same order of operations)."""
    r = c.ref
    rate = r.rate
    tz = np.tanh(c.z)
    mu = -lam * tz
    dmu = -lam * (1.0 - tz * tz)
    kv = matvec(frame.K, v)
    v_ref = matvec(frame.K_inv, c.x * (rate + mu))
    lifted_a = kv * (rate + mu + dmu) - c.x * rate * (rate + dmu) + np.exp(c.z) * r.x_r_ddot
    a_ref = matvec(frame.K_inv, lifted_a)
    return v - v_ref, v_ref, a_ref


class RobustUpdate:
    """The robust part of a law's θ̂ update (controllers/adaptation.py) for a batch of omni robots:
    the leakage σ₀ (θ̂ − P_T(θ̂)) subtracted from the law's θ̂̇, and the projection onto B after a step."""

    projects_estimate = True

    def __init__(self, law):
        band_lower, band_upper, lower, upper = law.adaptation.boxes(OmniRobot)
        self.sigma = law.adaptation.leakage
        self.band_lower, self.band_upper = (np.asarray(b, float)[:, None] for b in (band_lower, band_upper))
        self.lower, self.upper = (np.asarray(b, float)[:, None] for b in (lower, upper))

    def leak(self, theta_dot, estimate):
        """θ̂̇ −= σ₀ (ϑ − P_T(ϑ)) in place (the scalar law's floats, operation for operation)."""
        if self.sigma:
            excess = np.maximum(estimate, self.band_lower)
            np.minimum(excess, self.band_upper, out=excess)
            np.subtract(estimate, excess, out=excess)
            excess *= self.sigma
            theta_dot -= excess
        return theta_dot

    def project(self, theta_hat):
        """θ̂ projected onto B (EulerLagrangeModel.project)."""
        out = np.maximum(theta_hat, self.lower)
        return np.minimum(out, self.upper, out=out)


class CertaintyEquivalent(RobustUpdate):
    """(12)."""

    state_size = 0
    projects_estimate = True
    applied_input = None          # rows of the state that filter u_s (none)

    def __init__(self, law: CertaintyEquivalentLaw, n: int):
        super().__init__(law)
        self.lam = law.lam
        self.kp = diag_gain(law.Kp, n)[:, None]
        self.minus_kp = -self.kp
        self.gamma = law.gamma_theta

    def initial_state(self, z, p):
        return np.zeros((0, z.shape[1]))

    def evaluate(self, frame, c, v, theta_hat, state):
        p, v_ref, a_ref = _error_signals(frame, c, v, self.lam)
        u = np.multiply(self.minus_kp, p)
        u -= rmatvec(frame.K, np.divide(c.z, c.x))
        u += plant.regressor_times(v, v_ref, a_ref, theta_hat)
        theta_dot = plant.regressor_transpose_times(v, v_ref, a_ref, p)
        theta_dot /= -self.gamma
        return u, self.leak(theta_dot, theta_hat), None

    def estimate(self, theta_hat, state):
        return theta_hat


class OutputFeedbackBarrier(RobustUpdate):
    """The OF configuration's barrier law on the observer's v̂ (OutputFeedbackBarrierLaw)."""

    state_size = 0
    projects_estimate = True
    applied_input = None

    def __init__(self, law: OutputFeedbackBarrierLaw, n: int):
        super().__init__(law)
        self.lam = law.lam
        self.minus_kp = -diag_gain(law.Kp, n)[:, None]
        self.gamma = law.gamma_theta
        self.kb = law.barrier_weight

    def initial_state(self, z, p):
        return np.zeros((0, z.shape[1]))

    def evaluate(self, frame, c, v_hat, theta_hat, state):
        p_hat, v_ref, a_ref = _bounded_error_signals(frame, c, v_hat, self.lam)
        u = np.multiply(self.minus_kp, p_hat)
        slope = c.z + self.kb * np.minimum(c.z, 0.0)                              # V′(z)
        u -= rmatvec(frame.K, np.divide(slope, c.x))
        u += plant.regressor_times(v_hat, v_ref, a_ref, theta_hat)
        theta_dot = plant.regressor_transpose_times(v_hat, v_ref, a_ref, p_hat)
        theta_dot /= -self.gamma
        return u, self.leak(theta_dot, theta_hat), None

    def estimate(self, theta_hat, state):
        return theta_hat


class CompositeAdaptive(RobustUpdate):
    """(12) with the composite update on (14)–(15)'s filters; state rows [p_n (n), W_n (n·n_θ,
    row-major), u_n (n)]. `evaluate`'s rate leaves out u_s; the step adds it to the rows
    `applied_input` (CompositeAdaptiveLaw.with_applied_input)."""

    projects_estimate = True

    def __init__(self, law: CompositeAdaptiveLaw, n: int, n_theta: int):
        super().__init__(law)
        self.lam, self.k_q, self.alpha = law.lam, law.k_q, law.alpha_n
        self.gamma_theta, self.gamma_n, self.nu = law.gamma_theta, law.gamma_n, law.nu
        self.minus_kp = -diag_gain(law.Kp, n)[:, None]
        self.n, self.k = n, n_theta
        self.state_size = 2 * n + n * n_theta
        self.applied_input = slice(n + n * n_theta, self.state_size)

    def initial_state(self, z, p):
        """(15): p_n(0) = p(0)/(α_n − k_q), W_n(0) = 0; u_n(0) = 0. `p` is p at the take-over."""
        out = np.zeros((self.state_size, p.shape[1]))
        out[: self.n] = p / (self.alpha - self.k_q)
        return out

    def evaluate(self, frame, c, v, theta_hat, state):
        n, k = self.n, self.k
        p_n, u_n = state[:n], state[self.applied_input]
        W_n = state[n: n + n * k].reshape((n, k) + state.shape[1:])
        p, v_ref, a_ref = _error_signals(frame, c, v, self.lam)
        u = np.multiply(self.minus_kp, p)
        u -= rmatvec(frame.K, np.divide(c.z, c.x))
        u += plant.regressor_times(v, v_ref, a_ref, theta_hat)
        s = p + (self.k_q - self.alpha) * p_n
        W = plant.nce_regressor(v, p, v_ref, a_ref, self.k_q)
        Phi = plant.mass_regressor(s) - W_n
        error = matvec(Phi, theta_hat) - u_n                                   # Φ θ̂ − u_n
        gain = self.gamma_n / (1.0 + self.nu * np.sum(np.square(Phi), axis=(0, 1)))
        theta_dot = plant.regressor_transpose_times(v, v_ref, a_ref, p)
        theta_dot /= -self.gamma_theta
        theta_dot -= gain * rmatvec(Phi, error)
        self.leak(theta_dot, theta_hat)
        rate = np.empty_like(state)
        rate[:n] = -self.alpha * p_n + p
        rate[n: n + n * k] = (-self.alpha * W_n + W).reshape(n * k, -1)
        rate[self.applied_input] = -self.alpha * u_n
        return u, theta_dot, rate

    def estimate(self, theta_hat, state):
        return theta_hat


class OutputFeedback(RobustUpdate):
    """(25)–(29); state rows [z_f (n), ξ (n)]."""

    projects_estimate = True
    applied_input = None

    def __init__(self, law: OutputFeedbackLaw, n: int):
        super().__init__(law)
        self.n = n
        self.state_size = 2 * n
        self.k = law.k2 + 1.0
        self.k1 = diag_gain(law.K1, n)[:, None]
        self.stiffness, self.gamma, self.width = law.stiffness, law.gamma_theta, law.sign_width

    def initial_state(self, z, p):
        """z_f(0) = 0, ξ(0) = (k2 + 1) z(0) ((26), (28))."""
        return np.concatenate([np.zeros_like(z), self.k * z])

    def evaluate(self, frame, c, v_hat, theta_hat, state):
        n, k = self.n, self.k
        z_f, xi = state[:n], state[n:]
        z, r = c.z, c.ref
        r_f = xi - k * z
        ez = np.exp(z)
        w = matvec(frame.K_inv, ez * r.x_r_dot)
        w0_dot = matvec(frame.K_inv, ez * r.x_r_ddot)
        inner = -self.k1 * np.tanh((z + z_f) / self.width) + k * r_f - z
        u = rmatvec(frame.K, self.stiffness * inner / c.x) + plant.regressor_times(w, w, w0_dot, theta_hat)
        rate = np.concatenate([-z_f + r_f, -r_f - k * (z + r_f) + z - z_f])
        zd_hat = matvec(frame.K, v_hat) / c.x - r.rate
        eta_hat = zd_hat + z + r_f
        N_eta = matvec(frame.K_inv, c.x * eta_hat)
        theta_dot = -plant.regressor_transpose_times(w, w, w0_dot, N_eta) / self.gamma
        return u, self.leak(theta_dot, theta_hat), rate

    def estimate(self, theta_hat, state):
        return theta_hat


class Observer:
    """(40) on q: state rows [q̂ (n), β_o (n)], v̂ = β_o + K_a (q − q̂)."""

    def __init__(self, observer: VelocityObserver, n: int):
        ka, kb = diag_gain(observer.Ka, n), diag_gain(observer.Kb, n)
        if np.any(ka <= 1.0):
            raise ValueError("observer needs K_a > 1 so that K_c = K_a − I is positive")
        self.n, self.ka, self.kb, self.kc = n, ka[:, None], kb[:, None], (ka - 1.0)[:, None]
        self.width = observer.sign_width

    def initial_state(self, q0: np.ndarray) -> np.ndarray:
        """q̂(0) = q(0), β_o(0) = 0."""
        return np.concatenate([q0, np.zeros_like(q0)])

    def velocity(self, q, state):
        return state[self.n:] + self.ka * (q - state[: self.n])

    def derivative(self, q, state, out):
        q_tilde = q - state[: self.n]
        np.add(state[self.n:], self.ka * q_tilde, out=out[: self.n])
        np.add(self.kb * np.tanh(q_tilde / self.width), self.kc * q_tilde, out=out[self.n:])
        return out
