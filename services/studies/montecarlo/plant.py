"""The simulated robot's true dynamics (services/robot/plant.py) for a batch of robots.

Each robot has its own true θ = [m1, m3, a] (a payload, a heavier wheel), the friction, drive
limits and fail-safe brakes of `RobotSimConfig`, and `step` is `Plant.step` over the batch,
operation for operation: the wheel torques clamped to ±torque_limit and zeroed on a wheel at the
speed limit they would push further (at the step's start), the friction b ω + c tanh(ω/ω_s) and
the brakes c_b tanh(ω/ω_b) on the disarmed wheels, one RK4 step with all of them held.
tests/test_montecarlo_loop.py holds it to `Plant.step` to rounding.
"""
from __future__ import annotations

import numpy as np

from sharedctl.models import OmniRobot
from sharedctl.services.robot.plant import RobotSimConfig

DEFAULT_CONFIG = RobotSimConfig()


class PlantBatch:
    """`Plant` for N robots sharing a structure (OmniRobot's wheel map) and a `RobotSimConfig`."""

    def __init__(self, model: OmniRobot, theta: np.ndarray, config: RobotSimConfig = DEFAULT_CONFIG,
                 brake_torque: np.ndarray | None = None):
        self.wheel_map, self.config = model.wheel_map, config
        self.theta = np.asarray(theta, float)                 # (3, N): m1, m3, a per robot
        N = self.theta.shape[1]
        self.brake_torque = (np.full(N, config.brake_torque) if brake_torque is None
                             else np.broadcast_to(np.asarray(brake_torque, float), (N,)).copy())

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
