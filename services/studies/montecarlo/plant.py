"""The simulated robot's true dynamics (services/robot/plant.py) for a batch of robots.

Each robot has its own true θ = [m1, m3, a] (a payload, a heavier wheel), the friction, drive
limits and fail-safe brakes of `RobotSimConfig`, and `step` is `Plant.step` over the batch,
operation for operation: the wheel torques clamped to ±torque_limit and zeroed on a wheel at the
speed limit they would push further (at the step's start), the friction b ω + c tanh(ω/ω_s) and
the brakes c_b tanh(ω/ω_b) on the disarmed wheels, one RK4 step with all of them held.
tests/test_montecarlo_loop.py holds it to `Plant.step` to rounding.

Where numba is installed (the `montecarlo` extra), `step` runs compiled robot by robot (`_step_all`,
the same operations in the same order, libm's tanh, sin and cos for numpy's), unless the batch is
made with `compiled=False`; tests/test_montecarlo_loop.py holds the two together.
"""
from __future__ import annotations

import math

import numpy as np

from sharedctl.models import OmniRobot
from sharedctl.services.robot.plant import RobotSimConfig

try:                                    # optional: the `montecarlo` extra
    import numba
except ImportError:                     # pragma: no cover - exercised where numba is absent
    numba = None

DEFAULT_CONFIG = RobotSimConfig()


class PlantBatch:
    """`Plant` for N robots sharing a structure (OmniRobot's wheel map) and a `RobotSimConfig`."""

    def __init__(self, model: OmniRobot, theta: np.ndarray, config: RobotSimConfig = DEFAULT_CONFIG,
                 brake_torque: np.ndarray | None = None, compiled: bool | None = None):
        """`compiled`: step robot by robot with numba (None: where it is installed; True: required)."""
        if compiled and numba is None:
            raise ValueError("a compiled plant needs numba (the montecarlo extra)")
        self.compiled = numba is not None if compiled is None else bool(compiled)
        self.wheel_map, self.config = model.wheel_map, config
        self.theta = np.asarray(theta, float)                 # (3, N): m1, m3, a per robot
        N = self.theta.shape[1]
        self.brake_torque = (np.full(N, config.brake_torque) if brake_torque is None
                             else np.broadcast_to(np.asarray(brake_torque, float), (N,)).copy())
        m, c = self.wheel_map, config        # the compiled step's constants (`_step_all`)
        self._constants = np.array([m.s_r, m.c_r, m.one_r, m.l_r, c.torque_limit, c.wheel_speed_limit,
                                    c.friction_viscous, c.friction_coulomb, c.coulomb_smoothing, c.brake_smoothing])

    def drive_torque(self, tau: np.ndarray, omega: np.ndarray) -> np.ndarray:
        limit, speed_limit = self.config.torque_limit, self.config.wheel_speed_limit
        out = np.clip(tau, -limit, limit)
        return np.where((np.abs(omega) >= speed_limit) & (out * omega > 0), 0.0, out)

    def _derivative(self, q, v, tau_drive, brakes):
        c = self.config
        w = self.wheel_map.wheel_speeds_batch(q[2], v)
        t = tau_drive - (c.friction_viscous * w + c.friction_coulomb * np.tanh(w / c.coulomb_smoothing))
        t -= brakes * np.tanh(w / c.brake_smoothing)
        u = self.wheel_map.generalised_force_batch(q[2], t)
        m1, m3, a = self.theta
        qdd = np.stack(((u[0] - a * v[2] * v[1]) / m1, (u[1] + a * v[2] * v[0]) / m1, u[2] / m3))
        return v, qdd

    def step(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, disarmed: np.ndarray, dt: float):
        """One RK4 step of dt s: wheel torques τ (3, N) commanded, brakes on the `disarmed` (3, N) wheels."""
        if self.compiled:
            q_new, v_new = np.empty_like(q, dtype=float), np.empty_like(v, dtype=float)
            _step_all(self._constants, self.theta, self.brake_torque, np.ascontiguousarray(q, float),
                      np.ascontiguousarray(v, float), np.ascontiguousarray(tau, float),
                      np.ascontiguousarray(disarmed, bool), float(dt), q_new, v_new)
            return q_new, v_new
        tau_drive = self.drive_torque(tau, self.wheel_map.wheel_speeds_batch(q[2], v))
        brakes = np.where(disarmed, self.brake_torque, 0.0)
        h = 0.5 * dt
        k1 = self._derivative(q, v, tau_drive, brakes)
        k2 = self._derivative(q + h * k1[0], v + h * k1[1], tau_drive, brakes)
        k3 = self._derivative(q + h * k2[0], v + h * k2[1], tau_drive, brakes)
        k4 = self._derivative(q + dt * k3[0], v + dt * k3[1], tau_drive, brakes)
        w = dt / 6.0
        q_new = q + w * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
        v_new = v + w * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
        return q_new, v_new


def _jit(fn):
    return numba.njit(cache=True, error_model="numpy")(fn) if numba is not None else fn


@_jit
def _wheel_speeds(k, psi, v0, v1, v2):
    """WheelMap.wheel_speeds_batch for one robot."""
    cos, sin = math.cos(psi), math.sin(psi)
    bx, by = cos * v0 + sin * v1, cos * v1 - sin * v0
    x, y, z = k[0] * bx, k[1] * by, k[3] * v2
    return z - x + y, z - x - y, k[2] * bx + z


@_jit
def _derivative(k, m1, m3, a, q2, v0, v1, v2, d0, d1, d2, b0, b1, b2):
    """PlantBatch._derivative for one robot: q̈ from the drive torques d and the brakes b (per wheel)."""
    w0, w1, w2 = _wheel_speeds(k, q2, v0, v1, v2)
    visc, coul, smooth, brake = k[6], k[7], k[8], k[9]
    t0 = d0 - (visc * w0 + coul * math.tanh(w0 / smooth))
    t1 = d1 - (visc * w1 + coul * math.tanh(w1 / smooth))
    t2 = d2 - (visc * w2 + coul * math.tanh(w2 / smooth))
    t0 -= b0 * math.tanh(w0 / brake)
    t1 -= b1 * math.tanh(w1 / brake)
    t2 -= b2 * math.tanh(w2 / brake)
    fx = k[2] * t2 - k[0] * (t0 + t1)                 # WheelMap.generalised_force_batch
    fy = k[1] * (t0 - t1)
    cos, sin = math.cos(q2), math.sin(q2)
    u0, u1, u2 = cos * fx - sin * fy, sin * fx + cos * fy, k[3] * (t0 + t1 + t2)
    return (u0 - a * v2 * v1) / m1, (u1 + a * v2 * v0) / m1, u2 / m3


@_jit
def _drive(k, tau, omega):
    """PlantBatch.drive_torque for one wheel."""
    limit = k[4]
    if tau != tau:                                     # np.clip keeps a NaN
        return tau
    out = min(max(tau, -limit), limit)
    if abs(omega) >= k[5] and out * omega > 0:
        return 0.0
    return out


@_jit
def _step_all(k, theta, brake_torque, q, v, tau, disarmed, dt, q_new, v_new):
    """PlantBatch.step for every robot (columns), into q_new, v_new."""
    h = 0.5 * dt
    w = dt / 6.0
    for i in range(q.shape[1]):
        m1, m3, a = theta[0, i], theta[1, i], theta[2, i]
        x0, x1, x2, y0, y1, y2 = q[0, i], q[1, i], q[2, i], v[0, i], v[1, i], v[2, i]
        o0, o1, o2 = _wheel_speeds(k, x2, y0, y1, y2)
        d0, d1, d2 = _drive(k, tau[0, i], o0), _drive(k, tau[1, i], o1), _drive(k, tau[2, i], o2)
        c = brake_torque[i]
        b0 = c if disarmed[0, i] else 0.0
        b1 = c if disarmed[1, i] else 0.0
        b2 = c if disarmed[2, i] else 0.0
        a0, a1, a2 = _derivative(k, m1, m3, a, x2, y0, y1, y2, d0, d1, d2, b0, b1, b2)
        p0, p1, p2 = y0 + h * a0, y1 + h * a1, y2 + h * a2               # k2 at q + h k1
        e0, e1, e2 = _derivative(k, m1, m3, a, x2 + h * y2, p0, p1, p2, d0, d1, d2, b0, b1, b2)
        r0, r1, r2 = y0 + h * e0, y1 + h * e1, y2 + h * e2               # k3 at q + h k2
        f0, f1, f2 = _derivative(k, m1, m3, a, x2 + h * p2, r0, r1, r2, d0, d1, d2, b0, b1, b2)
        s0, s1, s2 = y0 + dt * f0, y1 + dt * f1, y2 + dt * f2            # k4 at q + dt k3
        g0, g1, g2 = _derivative(k, m1, m3, a, x2 + dt * r2, s0, s1, s2, d0, d1, d2, b0, b1, b2)
        q_new[0, i] = x0 + w * (y0 + 2.0 * p0 + 2.0 * r0 + s0)
        q_new[1, i] = x1 + w * (y1 + 2.0 * p1 + 2.0 * r1 + s1)
        q_new[2, i] = x2 + w * (y2 + 2.0 * p2 + 2.0 * r2 + s2)
        v_new[0, i] = y0 + w * (a0 + 2.0 * e0 + 2.0 * f0 + g0)
        v_new[1, i] = y1 + w * (a1 + 2.0 * e1 + 2.0 * f1 + g1)
        v_new[2, i] = y2 + w * (a2 + 2.0 * e2 + 2.0 * f2 + g2)
