"""True dynamics of the simulated robot: the omnidirectional model plus wheel friction and drive limits.

    M q̈ + C(q, q̇) q̇ = B(ψ) (τ_drive − τ_friction),   ω = B(ψ)ᵀ q̇   (the paper's omni3 model),
    τ_friction,j = b ω_j + c tanh(ω_j / ω_s)      (viscous + regularised Coulomb, per wheel),
    τ_brake,j    = c_b tanh(ω_j / ω_b) on a wheel whose drive is disarmed (fail-safe brake),
    τ_drive = clamp(τ, ±torque_limit), and 0 on a wheel already beyond the speed limit whose
              torque would push it further (the drive gives no further accelerating torque),
    d(wheel turns)/dt = ω / 2π.

Pure: no clocks, no I/O. `step(state, tau, dt)` is one RK4 step with τ held over the step.
When a drive is disarmed (idle, watchdog trip, estop, any fault) its wheel's fail-safe brake
engages, as an ODrive does with a mechanical brake on a GPIO ("when the drive enters a fault or
idle state, the brake will be re-engaged"; power-off, active-low brakes engage on power loss
too): a regularised Coulomb torque c_b = `brake_torque` per wheel. The default, 1.0 N·m, stops
the robot at about 2.4 m/s² — below the traction limit of its 9.85 kg body on wheels with a
friction coefficient ≥ 0.6 (the model has no wheel slip). `brake_torque = 0` is a robot without
brakes: it coasts on wheel friction alone (about 0.12 m/s²; docs/safety.md shows why the set is
then left after a loss of the drives at speed).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from sharedctl.models import OmniRobot

TWO_PI = 2.0 * math.pi


class RobotSimConfigError(ValueError):
    """A bad `[robot_sim]` key; the message names the key."""


@dataclass(frozen=True)
class RobotSimConfig:
    """`[robot_sim]` table of a scenario; every key optional."""

    friction_viscous: float = 0.01       # b, N·m·s/rad per wheel
    friction_coulomb: float = 0.05       # c, N·m per wheel
    brake_torque: float = 1.0            # c_b, N·m per wheel while its drive is disarmed (0: no brake)
    brake_smoothing: float = 0.2         # ω_b, rad/s (the brake's tanh width: stable at 1 kHz RK4)
    coulomb_smoothing: float = 0.05      # ω_s, rad/s (width of the tanh in the Coulomb term)
    torque_limit: float = 60.0           # N·m per wheel
    wheel_speed_limit: float = 60.0      # rad/s per wheel
    watchdog_timeout: float = 0.1        # s; 0 disables the drives' watchdogs
    encoder_rate_hz: float = 500.0       # cyclic Get_Encoder_Estimates per axis
    heartbeat_rate_hz: float = 10.0      # cyclic Heartbeat per axis
    physics_rate_hz: float = 1000.0      # RK4 steps per second
    truth_rate_hz: float = 100.0         # GroundTruth on Zenoh

    @classmethod
    def from_table(cls, table: object) -> "RobotSimConfig":
        """Validate a `[robot_sim]` mapping (None → defaults)."""
        if table is None:
            return cls()
        if not isinstance(table, dict):
            raise RobotSimConfigError("robot_sim must be a table")
        names = [f.name for f in fields(cls)]
        values = {}
        for key, value in table.items():
            if key not in names:
                raise RobotSimConfigError(f"unknown key robot_sim.{key} (allowed: {', '.join(names)})")
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise RobotSimConfigError(f"robot_sim.{key} must be a finite number, got {value!r}")
            value = float(value)
            if key in ("friction_viscous", "friction_coulomb", "watchdog_timeout", "brake_torque"):
                if value < 0:
                    raise RobotSimConfigError(f"robot_sim.{key} must be >= 0, got {value}")
            elif value <= 0:
                raise RobotSimConfigError(f"robot_sim.{key} must be > 0, got {value}")
            values[key] = value
        config = cls(**values)
        for key in ("encoder_rate_hz", "heartbeat_rate_hz", "truth_rate_hz"):
            if getattr(config, key) > config.physics_rate_hz:
                raise RobotSimConfigError(f"robot_sim.{key} must not exceed robot_sim.physics_rate_hz")
        if config.physics_rate_hz > 10000:
            raise RobotSimConfigError("robot_sim.physics_rate_hz must be <= 10000")
        return config


@dataclass(frozen=True)
class PlantState:
    """Pose q = [x, y, ψ] (m, m, rad), velocity q̇, wheel positions (turns)."""

    q: np.ndarray
    qd: np.ndarray
    wheel_turns: np.ndarray


class Plant:
    """The robot's true dynamics: `OmniRobot` (true θ) with wheel friction and drive limits."""

    def __init__(self, model: OmniRobot, config: RobotSimConfig = RobotSimConfig()) -> None:
        self.model = model
        self.config = config
        m1, m3, a = model.theta
        self._m1, self._m3, self._a = float(m1), float(m3), float(a)
        self._wheel_map = model.wheel_map          # B(ψ) in closed form, the model's own

    def initial_state(self, q0, qd0) -> PlantState:
        return PlantState(np.array(q0, dtype=float), np.array(qd0, dtype=float), np.zeros(3))

    def wheel_speeds(self, state: PlantState) -> tuple[float, float, float]:
        """ω = B(ψ)ᵀ q̇ (rad/s): the model's `WheelMap.wheel_speeds`."""
        return self._wheel_map.wheel_speeds(np.asarray(state.q, float).tolist(), np.asarray(state.qd, float).tolist())

    def friction(self, omega) -> np.ndarray:
        """Per-wheel friction torque (N·m), same sign as ω (it opposes the motion)."""
        c = self.config
        omega = np.asarray(omega, dtype=float)
        return c.friction_viscous * omega + c.friction_coulomb * np.tanh(omega / c.coulomb_smoothing)

    def drive_torque(self, tau, omega) -> tuple[float, float, float]:
        """τ clamped to the torque limit, zeroed on wheels beyond the speed limit it would accelerate."""
        assert len(tau) == 3, f"need three wheel torques, got {tau!r}"
        limit, speed_limit = self.config.torque_limit, self.config.wheel_speed_limit
        out = []
        for t, w in zip(tau, omega):
            t = float(t)
            assert math.isfinite(t), f"non-finite wheel torque {tau!r}"
            t = max(-limit, min(limit, t))
            out.append(0.0 if (abs(w) >= speed_limit and t * w > 0) else t)
        return tuple(out)

    def _derivative(self, q, qd, tau_drive, brakes=(0.0, 0.0, 0.0)):
        """(q̇, q̈, d turns/dt) as float tuples; ω = B(ψ)ᵀ q̇ and u = B(ψ) τ by the model's `WheelMap`.

        Plain floats rather than 3×3 numpy arrays: this runs 4000 times a second in real time.
        """
        b, c, ws = self.config.friction_viscous, self.config.friction_coulomb, self.config.coulomb_smoothing
        w0, w1, w2 = self._wheel_map.wheel_speeds(q, qd)
        t0 = tau_drive[0] - (b * w0 + c * math.tanh(w0 / ws))
        t1 = tau_drive[1] - (b * w1 + c * math.tanh(w1 / ws))
        t2 = tau_drive[2] - (b * w2 + c * math.tanh(w2 / ws))
        if brakes[0] or brakes[1] or brakes[2]:
            wb = self.config.brake_smoothing
            t0 -= brakes[0] * math.tanh(w0 / wb)
            t1 -= brakes[1] * math.tanh(w1 / wb)
            t2 -= brakes[2] * math.tanh(w2 / wb)
        u0, u1, u2 = self._wheel_map.generalised_force(q, (t0, t1, t2))
        vx, vy, w = qd
        qdd = ((u0 - self._a * w * vy) / self._m1, (u1 + self._a * w * vx) / self._m1, u2 / self._m3)
        return qd, qdd, (w0 / TWO_PI, w1 / TWO_PI, w2 / TWO_PI)

    def brake_torques(self, engaged) -> tuple[float, float, float]:
        """c_b on each wheel whose brake is engaged (its drive disarmed), else 0."""
        c_b = self.config.brake_torque
        return tuple(c_b if e else 0.0 for e in engaged)

    def step(self, state: PlantState, tau, dt: float, brakes=(0.0, 0.0, 0.0)) -> PlantState:
        """One RK4 step of length dt (s) with the commanded wheel torques τ (N·m) and the brake
        torques (N·m, `brake_torques(engaged)`) held."""
        q = tuple(float(v) for v in state.q)
        qd = tuple(float(v) for v in state.qd)
        tau_drive = self.drive_torque(tau, self._wheel_map.wheel_speeds(q, qd))
        h = 0.5 * dt

        def shift(x, k, f):
            return (x[0] + f * k[0], x[1] + f * k[1], x[2] + f * k[2])

        k1 = self._derivative(q, qd, tau_drive, brakes)
        k2 = self._derivative(shift(q, k1[0], h), shift(qd, k1[1], h), tau_drive, brakes)
        k3 = self._derivative(shift(q, k2[0], h), shift(qd, k2[1], h), tau_drive, brakes)
        k4 = self._derivative(shift(q, k3[0], dt), shift(qd, k3[1], dt), tau_drive, brakes)
        w = dt / 6.0
        incr = [[w * (k1[i][j] + 2.0 * k2[i][j] + 2.0 * k3[i][j] + k4[i][j]) for j in range(3)] for i in range(3)]
        q_new = np.array([q[j] + incr[0][j] for j in range(3)])
        qd_new = np.array([qd[j] + incr[1][j] for j in range(3)])
        turns_new = np.array([float(state.wheel_turns[j]) + incr[2][j] for j in range(3)])
        assert all(math.isfinite(v) for v in (*q_new, *qd_new)), "physics produced a non-finite state"
        return PlantState(q_new, qd_new, turns_new)

    def kinetic_energy(self, state: PlantState) -> float:
        """½ q̇ᵀ M q̇ (J)."""
        return 0.5 * float(state.qd @ self.model.mass(state.q) @ state.qd)
