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

The wheel map in closed form (`WheelMap`). Each wheel's drive direction turns with the body
and the L_r row does not, so B(ψ) is the body-frame matrix turned by the yaw:

    B(ψ) = blockdiag(R(ψ), 1) · B(0),   R(ψ) = [[cos ψ, −sin ψ], [sin ψ, cos ψ]],
    B(0) = (1/r) [[−s, −s, 1], [c, −c, 0], [L_r, L_r, L_r]],   s = sin δ, c = cos δ.

det B(0) = 2 c L_r (1 + s) / r³ (≠ 0 for |δ| < π/2, L_r > 0), and

    B(0)⁻¹ = r [[−1/(2(1+s)),  1/(2c), 1/(2L_r(1+s))],
                [−1/(2(1+s)), −1/(2c), 1/(2L_r(1+s))],
                [  1/(1+s),      0,    s/(L_r(1+s))  ]].

With the body-frame force f = R(ψ)ᵀ[u_x, u_y] and velocity b = R(ψ)ᵀ[ẋ, ẏ]:

    τ = B(ψ)⁻¹ u  = B(0)⁻¹ [f, u_ψ]               (the wheel torques that realise u)
    ω = B(ψ)ᵀ q̇   = B(0)ᵀ [b, ψ̇]                  (what the wheel encoders see)
    q̇ = B(ψ)⁻ᵀ ω  = blockdiag(R(ψ), 1) B(0)⁻ᵀ ω    (odometry)
    u = B(ψ) τ    = blockdiag(R(ψ), 1) B(0) τ      (the generalised force of the wheel torques)

— one cos, one sin and a dozen products per call on Python floats, where `np.linalg.solve` on a
freshly built 3×3 costs microseconds. The coefficients depend only on the fixed parameters, so the
model computes them once. A non-finite yaw gives NaN components (as the numpy solve does) and a
non-finite input non-finite ones, never an exception: the controller's finiteness check turns
either into an estop. `input_matrix` stays the printed B(ψ), the reference the closed form is
tested against.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .base import EulerLagrangeModel

_cos, _sin, _isfinite, _NAN = math.cos, math.sin, math.isfinite, math.nan   # one lookup each (`WheelMap`)


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
class WheelMap:
    """B(ψ) = blockdiag(R(ψ), 1) · B(0) and its inverse on Python floats (see the module docstring).

    Every method takes the pose q (only its yaw ψ = q[2] is used) and a 3-sequence of floats, and
    returns a 3-tuple of floats. A non-finite yaw makes cos ψ = sin ψ = NaN (`math.cos(inf)` raises;
    the numpy solve gives NaN); each method writes that out rather than calling a helper, which
    would cost as much as its arithmetic in the simulated robot's 4 kHz RK4 stages.
    """

    s_r: float      # sin δ / r    }
    c_r: float      # cos δ / r    } B(0) = [[−s_r, −s_r, 1/r], [c_r, −c_r, 0], [L_r/r, L_r/r, L_r/r]]
    one_r: float    # 1 / r        }
    l_r: float      # L_r / r      }
    k_x: float      # r / (2(1 + s))        }
    k_y: float      # r / (2c)              } B(0)⁻¹ = [[−k_x, k_y, k_m], [−k_x, −k_y, k_m], [2k_x, 0, k_s]]
    k_m: float      # r / (2L_r(1 + s))     }
    k_s: float      # r s / (L_r(1 + s))    }

    @classmethod
    def of(cls, parameters: OmniRobotParameters) -> "WheelMap":
        r, L, delta = parameters.wheel_radius, parameters.wheel_distance, parameters.delta
        s, c = math.sin(delta), math.cos(delta)
        if r == 0.0 or L == 0.0 or c == 0.0 or 1.0 + s == 0.0:
            raise ValueError(f"B(0) is singular for r={r}, L_r={L}, δ={delta}: no wheel map")
        return cls(s_r=s / r, c_r=c / r, one_r=1.0 / r, l_r=L / r,
                   k_x=r / (2.0 * (1.0 + s)), k_y=r / (2.0 * c), k_m=r / (2.0 * L * (1.0 + s)),
                   k_s=r * s / (L * (1.0 + s)))

    def wheel_torques(self, q, u) -> tuple[float, float, float]:
        """τ = B(0)⁻¹ [R(ψ)ᵀ [u_x, u_y], u_ψ] = B(ψ)⁻¹ u (N·m)."""
        psi = q[2]
        if _isfinite(psi):
            cos, sin = _cos(psi), _sin(psi)
        else:
            cos = sin = _NAN
        ux, uy, m = u
        fx, fy = cos * ux + sin * uy, cos * uy - sin * ux          # the force in the body frame
        x, y, z = self.k_x * fx, self.k_y * fy, self.k_m * m
        return z - x + y, z - x - y, 2.0 * x + self.k_s * m

    def body_velocity(self, q, omega) -> tuple[float, float, float]:
        """q̇ = blockdiag(R(ψ), 1) B(0)⁻ᵀ ω = B(ψ)⁻ᵀ ω (or Δq for wheel angle increments Δφ)."""
        w0, w1, w2 = omega
        pair = w0 + w1
        bx = self.k_x * (2.0 * w2 - pair)                         # the velocity in the body frame
        by = self.k_y * (w0 - w1)
        psi = q[2]
        if _isfinite(psi):
            cos, sin = _cos(psi), _sin(psi)
        else:
            cos = sin = _NAN
        return cos * bx - sin * by, sin * bx + cos * by, self.k_m * pair + self.k_s * w2

    def wheel_speeds(self, q, v) -> tuple[float, float, float]:
        """ω = B(0)ᵀ [R(ψ)ᵀ [ẋ, ẏ], ψ̇] = B(ψ)ᵀ q̇ (rad/s)."""
        psi = q[2]
        if _isfinite(psi):
            cos, sin = _cos(psi), _sin(psi)
        else:
            cos = sin = _NAN
        vx, vy, w = v
        bx, by = cos * vx + sin * vy, cos * vy - sin * vx           # the velocity in the body frame
        x, y, z = self.s_r * bx, self.c_r * by, self.l_r * w
        return z - x + y, z - x - y, self.one_r * bx + z

    def generalised_force(self, q, tau) -> tuple[float, float, float]:
        """u = blockdiag(R(ψ), 1) B(0) τ = B(ψ) τ."""
        t0, t1, t2 = tau
        fx = self.one_r * t2 - self.s_r * (t0 + t1)                # the force in the body frame
        fy = self.c_r * (t0 - t1)
        psi = q[2]
        if _isfinite(psi):
            cos, sin = _cos(psi), _sin(psi)
        else:
            cos = sin = _NAN
        return cos * fx - sin * fy, sin * fx + cos * fy, self.l_r * (t0 + t1 + t2)

    # ----- the same arithmetic over a batch: psi (N,), vectors (3, N) → (3, N) ------------------------
    def wheel_torques_batch(self, psi: np.ndarray, u: np.ndarray) -> np.ndarray:
        """τ = B(ψ)⁻¹ u for every column (`wheel_torques`, elementwise)."""
        cos, sin = np.cos(psi), np.sin(psi)
        fx, fy = cos * u[0] + sin * u[1], cos * u[1] - sin * u[0]
        x, y, z = self.k_x * fx, self.k_y * fy, self.k_m * u[2]
        return np.stack((z - x + y, z - x - y, 2.0 * x + self.k_s * u[2]))

    def wheel_speeds_batch(self, psi: np.ndarray, v: np.ndarray) -> np.ndarray:
        """ω = B(ψ)ᵀ q̇ for every column (`wheel_speeds`, elementwise)."""
        cos, sin = np.cos(psi), np.sin(psi)
        bx, by = cos * v[0] + sin * v[1], cos * v[1] - sin * v[0]
        x, y, z = self.s_r * bx, self.c_r * by, self.l_r * v[2]
        return np.stack((z - x + y, z - x - y, self.one_r * bx + z))

    def generalised_force_batch(self, psi: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """u = B(ψ) τ for every column (`generalised_force`, elementwise)."""
        t0, t1, t2 = tau
        fx = self.one_r * t2 - self.s_r * (t0 + t1)
        fy = self.c_r * (t0 - t1)
        cos, sin = np.cos(psi), np.sin(psi)
        return np.stack((cos * fx - sin * fy, sin * fx + cos * fy, self.l_r * (t0 + t1 + t2)))


@dataclass(frozen=True)
class OmniRobot(EulerLagrangeModel):
    """Omnidirectional robot, `kind = "omni3"` in scenario files."""

    parameters: OmniRobotParameters = field(default_factory=OmniRobotParameters)
    #: the wheel map B(ψ) in closed form, computed once from the (fixed) parameters
    wheel_map: WheelMap = field(init=False, repr=False, compare=False)
    n = 3
    n_theta = 3
    coordinate_names = ("x", "y", "psi")
    parameter_names = ("m1", "m3", "a")
    # m1 (kg), m3 (kg m²), a (kg). The physical box: this robot with a payload of up to its own effective
    # mass (m1 ≤ 36 kg: 18 kg on the 9.85 kg body), its yaw inertia and its wheels' term a = 3I_r/(2r²)
    # at most doubled; the trust box: up to 1.5 times the nominal θ. 0 admits the paper's θ̂(0) = 0
    # (no prior from below). docs/control.md §11
    theta_lower = (0.0, 0.0, 0.0)
    theta_upper = (36.0, 2.4, 16.4)
    theta_band_lower = (0.0, 0.0, 0.0)
    theta_band_upper = (27.0, 1.8, 12.3)

    def __post_init__(self) -> None:
        object.__setattr__(self, "wheel_map", WheelMap.of(self.parameters))

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

    # ----- the wheel map (`WheelMap`, in closed form) on numpy vectors; the 500 Hz controller
    # calls `wheel_map` on Python floats directly ----------------------------------------------
    def wheel_torques(self, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """τ = B(ψ)⁻¹ u: the wheel torques (N·m) that realise the generalised force u."""
        return np.array(self.wheel_map.wheel_torques(_floats(q), _floats(u)))

    def wheel_speeds(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """ω = B(ψ)ᵀ q̇ (rad/s): what the wheel encoders see."""
        return np.array(self.wheel_map.wheel_speeds(_floats(q), _floats(v)))

    def body_velocity_from_wheels(self, q: np.ndarray, wheel_speeds: np.ndarray) -> np.ndarray:
        """q̇ = B(ψ)⁻ᵀ ω: odometry from the wheel encoders."""
        return np.array(self.wheel_map.body_velocity(_floats(q), _floats(wheel_speeds)))


def _floats(x) -> list:
    """A 3-vector as Python floats (numpy scalars would warn on inf − inf instead of quietly giving NaN)."""
    return np.asarray(x, dtype=float).tolist()
