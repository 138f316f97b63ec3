"""The paper's three-wheel omnidirectional robot (Section 5; Liu et al. 2008, ref. [17]).

q = [x, y, ψ] (m, m, rad): centre of mass in the world frame and yaw.
M = diag(m1, m1, m3), C(q, q̇) = a ψ̇ [[0, 1, 0], [−1, 0, 0], [0, 0, 0]], g = 0,
u = B(ψ) τ with τ the three wheel torques (N·m) and
B(ψ) = (1/r) [[−sin(δ+ψ), −sin(δ−ψ), cos ψ],
              [ cos(δ+ψ), −cos(δ−ψ), sin ψ],
              [ L_r,        L_r,       L_r ]].
θ = [m1, m3, a] with m1 = M_p + 3I_r/(2r²), m3 = I_p + 3I_r L_r²/r², a = 3I_r/(2r²).
Wheel speeds are ω = Bᵀ q̇ (power balance uᵀq̇ = τᵀω). C is skew-symmetric and M is
constant, so Ṁ − 2C is skew-symmetric as the passivity property requires.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .base import EulerLagrangeModel


@dataclass(frozen=True)
class OmniRobotParameters:
    """Physical parameters; defaults are the paper's (Section 5)."""

    mass: float = 9.85               # M_p, kg
    body_inertia: float = 0.522      # I_p, kg m²
    wheel_inertia: float = 0.0086    # I_r, kg m²
    wheel_radius: float = 0.03965    # r, m
    wheel_distance: float = 0.205    # L_r, m (centre of mass to each wheel)
    delta: float = math.pi / 6       # δ, rad

    def theta(self) -> np.ndarray:
        """θ = [m1, m3, a]."""
        r2 = self.wheel_radius**2
        m1 = self.mass + 3.0 * self.wheel_inertia / (2.0 * r2)
        m3 = self.body_inertia + 3.0 * self.wheel_inertia * self.wheel_distance**2 / r2
        a = 3.0 * self.wheel_inertia / (2.0 * r2)
        return np.array([m1, m3, a])


@dataclass(frozen=True)
class OmniRobot(EulerLagrangeModel):
    """Omnidirectional robot, `kind = "omni3"` in scenario files."""

    parameters: OmniRobotParameters = field(default_factory=OmniRobotParameters)
    n = 3
    n_theta = 3
    coordinate_names = ("x", "y", "psi")
    parameter_names = ("m1", "m3", "a")
    # a wheeled robot of up to ~200 kg: m1 (kg), m3 (kg m²), a (kg); 0 admits the paper's θ̂(0) = 0
    theta_lower = (0.0, 0.0, 0.0)
    theta_upper = (200.0, 50.0, 100.0)

    @property
    def theta(self) -> np.ndarray:
        return self.parameters.theta()

    def mass_regressor(self, q, a):
        return np.array([[a[0], 0.0, 0.0], [a[1], 0.0, 0.0], [0.0, a[2], 0.0]])

    def coriolis_regressor(self, q, v, w):
        psi_dot = v[2]
        return np.array([[0.0, 0.0, psi_dot * w[1]], [0.0, 0.0, -psi_dot * w[0]], [0.0, 0.0, 0.0]])

    def regressor(self, q, v, w, a):
        """Y = Y_M(a) + Y_C(v, w) + Y_g, written out (g = 0): one array instead of three and two sums."""
        a0, a1, a2 = a.tolist()
        psi_dot = float(v[2])
        return np.array([[a0, 0.0, psi_dot * float(w[1])], [a1, 0.0, -psi_dot * float(w[0])], [0.0, a2, 0.0]])

    def regressor_rows(self, q, v, w, a):
        """`regressor` on Python floats: [[a0, 0, ψ̇ w1], [a1, 0, −ψ̇ w0], [0, a2, 0]]."""
        psi_dot = v[2]
        return [[a[0], 0.0, psi_dot * w[1]], [a[1], 0.0, -psi_dot * w[0]], [0.0, a[2], 0.0]]

    def mass_regressor_rows(self, q, a):
        return [[a[0], 0.0, 0.0], [a[1], 0.0, 0.0], [0.0, a[2], 0.0]]

    def coriolis_regressor_rows(self, q, v, w):
        psi_dot = v[2]
        return [[0.0, 0.0, psi_dot * w[1]], [0.0, 0.0, -psi_dot * w[0]], [0.0, 0.0, 0.0]]

    def mass_rate_regressor_rows(self, q, v, b):
        return [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]

    def gravity_regressor(self, q):
        return np.zeros((3, 3))

    def mass_rate_regressor(self, q, v, b):
        return np.zeros((3, 3))

    def mass(self, q, theta=None):
        th = self.theta if theta is None else theta
        return np.diag([th[0], th[0], th[1]])

    def acceleration(self, q, v, u):
        m1, m3, a = self.theta
        psi_dot = v[2]
        return np.array([(u[0] - a * psi_dot * v[1]) / m1, (u[1] + a * psi_dot * v[0]) / m1, u[2] / m3])

    def input_matrix(self, q):
        p = self.parameters
        psi, d = q[2], p.delta
        return (1.0 / p.wheel_radius) * np.array(
            [
                [-math.sin(d + psi), -math.sin(d - psi), math.cos(psi)],
                [math.cos(d + psi), -math.cos(d - psi), math.sin(psi)],
                [p.wheel_distance, p.wheel_distance, p.wheel_distance],
            ]
        )

    def wheel_torques(self, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """τ = B(ψ)⁻¹ u: the wheel torques (N·m) that realise the generalised force u."""
        return np.linalg.solve(self.input_matrix(q), u)

    def wheel_speeds(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """ω = B(ψ)ᵀ q̇ (rad/s): what the wheel encoders see."""
        return self.input_matrix(q).T @ v

    def body_velocity_from_wheels(self, q: np.ndarray, wheel_speeds: np.ndarray) -> np.ndarray:
        """q̇ = B(ψ)⁻ᵀ ω: odometry from the wheel encoders."""
        return np.linalg.solve(self.input_matrix(q).T, wheel_speeds)
