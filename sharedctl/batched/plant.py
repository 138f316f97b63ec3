"""The omnidirectional robot of models/omni_robot.py for a whole batch (paper (1), Section 5).

M = diag(m1, m1, m3), C(q, q̇) = a ψ̇ [[0, 1, 0], [−1, 0, 0], [0, 0, 0]], g = 0, θ = [m1, m3, a].
The regressor Y(q, v, w, a) θ = M a + C(q, v) w + g of (11) is

    Y = [[a₀, 0, ψ̇ w₁], [a₁, 0, −ψ̇ w₀], [0, a₂, 0]],   ψ̇ = v₂,

so every product the laws need (Y θ̂, Yᵀ p, Y_M, and the matrix W of (14)) is a handful of
elementwise operations on (3, N) arrays. Each robot may have its own true θ (mass, inertia).
"""
from __future__ import annotations

import numpy as np

from ..models.omni_robot import OmniRobot

try:                                    # optional: the `montecarlo` extra
    import numba
except ImportError:                     # pragma: no cover - exercised where numba is absent
    numba = None


class BatchPlantError(TypeError):
    """A model the batch has no vectorised form for."""


def check_model(model) -> None:
    if not isinstance(model, OmniRobot):
        raise BatchPlantError(f"the batched simulator covers the omni robot only, got {type(model).__name__}")


def acceleration(theta: np.ndarray, v: np.ndarray, u: np.ndarray, out: np.ndarray) -> np.ndarray:
    """q̈ = M⁻¹(u − C q̇) with the true θ (3, N), written into `out` (3, N)."""
    m1, m3, a = theta
    a_psi = a * v[2]
    np.divide(u[0] - a_psi * v[1], m1, out=out[0])
    np.divide(u[1] + a_psi * v[0], m1, out=out[1])
    np.divide(u[2], m3, out=out[2])
    return out


def predict_rings(theta, ring, count, use, history: int, dt: float, q, v) -> None:
    """shared_controller.predict for every robot (columns), in place on q, v (3, N): robot i's last
    use[i] commands of its ring `ring`[:, i·history : (i + 1)·history] (`count`[i] written so far,
    oldest first), each held dt — per period the acceleration at its start (`acceleration`'s
    operations), q += q̇ dt + ½a dt², q̇ += a dt. Compiled robot by robot where numba is installed
    (`predict_rings_compiled`; the same operations in the same order)."""
    half = 0.5 * dt * dt
    for i in range(q.shape[1]):
        m1, m3, ath = theta[0, i], theta[1, i], theta[2, i]
        q0, q1, q2, v0, v1, v2 = q[0, i], q[1, i], q[2, i], v[0, i], v[1, i], v[2, i]
        for j in range(use[i]):
            slot = i * history + (count[i] - use[i] + j) % history
            a_psi = ath * v2
            a0 = (ring[0, slot] - a_psi * v1) / m1
            a1 = (ring[1, slot] + a_psi * v0) / m1
            a2 = ring[2, slot] / m3
            q0 = q0 + dt * v0 + half * a0
            q1 = q1 + dt * v1 + half * a1
            q2 = q2 + dt * v2 + half * a2
            v0 = v0 + dt * a0
            v1 = v1 + dt * a1
            v2 = v2 + dt * a2
        q[0, i], q[1, i], q[2, i], v[0, i], v[1, i], v[2, i] = q0, q1, q2, v0, v1, v2


predict_rings_compiled = numba.njit(cache=True, error_model="numpy")(predict_rings) if numba is not None else None


def regressor_times(v, w, a, theta) -> np.ndarray:
    """Y(q, v, w, a) θ for every robot: [a₀θ₀ + ψ̇w₁θ₂, a₁θ₀ − ψ̇w₀θ₂, a₂θ₁]."""
    psi = v[2]
    out = np.empty(a.shape)
    t = np.multiply(psi, w[1])
    t *= theta[2]
    np.multiply(a[0], theta[0], out=out[0])
    out[0] += t
    np.multiply(psi, w[0], out=t)
    t *= theta[2]
    np.multiply(a[1], theta[0], out=out[1])
    out[1] -= t
    np.multiply(a[2], theta[1], out=out[2])
    return out


def regressor_transpose_times(v, w, a, p) -> np.ndarray:
    """Y(q, v, w, a)ᵀ p for every robot: [a₀p₀ + a₁p₁, a₂p₂, ψ̇w₁p₀ − ψ̇w₀p₁]."""
    psi = v[2]
    out = np.empty(a.shape)
    t = np.multiply(a[1], p[1])
    np.multiply(a[0], p[0], out=out[0])
    out[0] += t
    np.multiply(a[2], p[2], out=out[1])
    np.multiply(psi, w[1], out=out[2])
    out[2] *= p[0]
    np.multiply(psi, w[0], out=t)
    t *= p[1]
    out[2] -= t
    return out


def mass_regressor(a) -> np.ndarray:
    """Y_M(q, a) with Y_M θ = M a for every robot: [[a₀, 0, 0], [a₁, 0, 0], [0, a₂, 0]], shape (3, 3, N)."""
    Y = np.zeros((3, 3) + a.shape[1:])
    Y[0, 0], Y[1, 0], Y[2, 1] = a[0], a[1], a[2]
    return Y


def nce_regressor(v, p, v_ref, a_ref, k_q: float) -> np.ndarray:
    """W = Ṁ s + k_q M p − C(q, v) p − Y(q, v, v_ref, a_ref) of (14) (Ṁ = 0), shape (3, 3, N)."""
    psi = v[2]
    W = np.zeros((3, 3) + v.shape[1:])
    W[0, 0] = k_q * p[0] - a_ref[0]
    W[1, 0] = k_q * p[1] - a_ref[1]
    W[2, 1] = k_q * p[2] - a_ref[2]
    W[0, 2] = -(psi * p[1]) - psi * v_ref[1]
    W[1, 2] = -(-psi * p[0]) - (-psi * v_ref[0])
    return W


def project(theta_hat: np.ndarray) -> np.ndarray:
    """The omni robot's parameter box (EulerLagrangeModel.project)."""
    out = np.maximum(theta_hat, _LOWER)       # np.clip's result, without its overhead
    return np.minimum(out, _UPPER, out=out)


_LOWER = np.asarray(OmniRobot.theta_lower, float)[:, None]
_UPPER = np.asarray(OmniRobot.theta_upper, float)[:, None]


def wheel_torques(q: np.ndarray, u: np.ndarray, model: OmniRobot) -> np.ndarray:
    """τ = B(ψ)⁻¹ u for rows of q, u (T, 3) (for traces)."""
    p = model.parameters
    psi, d = q[:, 2], p.delta
    B = np.zeros((q.shape[0], 3, 3))
    B[:, 0, 0], B[:, 0, 1], B[:, 0, 2] = -np.sin(d + psi), -np.sin(d - psi), np.cos(psi)
    B[:, 1, 0], B[:, 1, 1], B[:, 1, 2] = np.cos(d + psi), -np.cos(d - psi), np.sin(psi)
    B[:, 2, :] = p.wheel_distance
    B /= p.wheel_radius
    good = np.all(np.isfinite(u), axis=1) & np.isfinite(psi)
    out = np.full(u.shape, np.nan)
    if good.any():
        out[good] = np.linalg.solve(B[good], u[good][:, :, None])[:, :, 0]
    return out
