"""The omni robot's wheel map per control period, on Python floats: q̇ = B(ψ)⁻ᵀ ω and τ = B(ψ)⁻¹ u.

The robot's input matrix (`OmniRobot.input_matrix`, the paper's Section 5) is the body-frame
matrix B(0) turned by the yaw:

    B(ψ) = blockdiag(R(ψ), 1) · B(0),   R(ψ) = [[cos ψ, −sin ψ], [sin ψ, cos ψ]]

(each wheel's drive direction turns with the body; the L_r row does not). Hence, with the constant
C = B(0)⁻¹ inverted once at start-up,

    q̇ = B(ψ)⁻ᵀ ω = blockdiag(R(ψ), 1) · Cᵀ ω        (odometry: the body velocity turned into the world)
    τ = B(ψ)⁻¹ u  = C · blockdiag(R(ψ), 1)ᵀ u         (the wheel torques that realise u)

— nine multiplications and one rotation per call, where `np.linalg.solve` on a freshly built 3×3
costs tens of microseconds at 500 Hz. `WheelKinematics.for_model` checks that factorisation against
the model's own `input_matrix` at several poses and otherwise falls back to the model's
`body_velocity_from_wheels` / `wheel_torques`, so a model with another geometry stays correct.

A non-finite yaw or input gives NaN components (as the numpy solve does), never an exception: the
daemon's finiteness check turns that into an estop.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: yaws at which the factorisation is checked against the model (rad; at x, y ≠ 0)
CHECK_YAWS = (0.0, 0.7, -1.9, 2.6, math.pi)
CHECK_TOLERANCE = 1e-9   # relative to the largest entry of B


@dataclass(frozen=True)
class WheelKinematics:
    """q̇ = B(ψ)⁻ᵀ ω and τ = B(ψ)⁻¹ u for a robot whose B(ψ) = blockdiag(R(ψ), 1) · B(0)."""

    c: tuple[tuple[float, float, float], ...]   # C = B(0)⁻¹, row-major

    @classmethod
    def for_model(cls, model) -> "WheelKinematics | ModelKinematics":
        """The closed form when `model.input_matrix` factors as above, else the model's own solves."""
        try:
            b0 = np.asarray(model.input_matrix(np.zeros(3)), dtype=float)
            if b0.shape != (3, 3) or not np.all(np.isfinite(b0)):
                return ModelKinematics(model)
            scale = float(np.max(np.abs(b0)))
            for psi in CHECK_YAWS:
                turn = np.array([[math.cos(psi), -math.sin(psi), 0.0], [math.sin(psi), math.cos(psi), 0.0],
                                 [0.0, 0.0, 1.0]])
                b = np.asarray(model.input_matrix(np.array([1.3, -0.7, psi])), dtype=float)
                if not np.allclose(b, turn @ b0, rtol=0.0, atol=CHECK_TOLERANCE * scale):
                    return ModelKinematics(model)
            c = np.linalg.inv(b0)
        except (AttributeError, TypeError, ValueError, np.linalg.LinAlgError):
            return ModelKinematics(model)
        return cls(tuple(tuple(float(x) for x in row) for row in c))

    def body_velocity(self, q, w) -> tuple[float, float, float]:
        """q̇ = B(ψ)⁻ᵀ ω at the pose q (or Δq for wheel angle increments Δφ), as (ẋ, ẏ, ψ̇)."""
        w0, w1, w2 = w
        (c00, c01, c02), (c10, c11, c12), (c20, c21, c22) = self.c
        bx = c00 * w0 + c10 * w1 + c20 * w2          # Cᵀ ω: the velocity in the body frame
        by = c01 * w0 + c11 * w1 + c21 * w2
        dpsi = c02 * w0 + c12 * w1 + c22 * w2
        cos, sin = _cos_sin(q[2])
        return cos * bx - sin * by, sin * bx + cos * by, dpsi

    def wheel_torques(self, q, u) -> tuple[float, float, float]:
        """τ = B(ψ)⁻¹ u at the pose q."""
        u0, u1, u2 = u
        cos, sin = _cos_sin(q[2])
        bx, by = cos * u0 + sin * u1, -sin * u0 + cos * u1   # R(ψ)ᵀ u: the force in the body frame
        (c00, c01, c02), (c10, c11, c12), (c20, c21, c22) = self.c
        return (c00 * bx + c01 * by + c02 * u2, c10 * bx + c11 * by + c12 * u2, c20 * bx + c21 * by + c22 * u2)


@dataclass(frozen=True)
class ModelKinematics:
    """The same interface on the model's own numpy solves (any geometry)."""

    model: object

    def body_velocity(self, q, w) -> tuple[float, float, float]:
        v = self.model.body_velocity_from_wheels(np.asarray(q, dtype=float), np.asarray(w, dtype=float))
        return float(v[0]), float(v[1]), float(v[2])

    def wheel_torques(self, q, u) -> tuple[float, float, float]:
        tau = self.model.wheel_torques(np.asarray(q, dtype=float), np.asarray(u, dtype=float))
        return float(tau[0]), float(tau[1]), float(tau[2])


def _cos_sin(psi: float) -> tuple[float, float]:
    if not math.isfinite(psi):          # math.cos(inf) raises; the numpy solve gives NaN
        return math.nan, math.nan
    return math.cos(psi), math.sin(psi)
