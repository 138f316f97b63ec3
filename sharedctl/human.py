"""Human operator models (paper Section 3.4).

The joystick spring (44): the handle is deflected q̂_h from the tracked position and the
operator's generalised force is u_h = k_p q̂_h. The intent measure (45) is
v_h = ½ Σ_j k_p,j q̂_h,j² (the spring's stored energy; 0 only with the handle centred).

Every model answers two questions at time t for the robot state (q, q̇):
`desired(t)` — the trajectory the operator intends (q_d, q̇_d, q̈_d), from which the
machine builds its projected reference — and `command(t, q, v)` — the deflection q̂_h
and the force u_h.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .transform import Desired


# ----- desired trajectories --------------------------------------------------
class Trajectory(ABC):
    @abstractmethod
    def sample(self, t: float) -> Desired:
        """q_d(t), q̇_d(t), q̈_d(t)."""


@dataclass(frozen=True)
class LineTrajectory(Trajectory):
    """q_d = start + velocity · t."""

    start: np.ndarray
    velocity: np.ndarray

    def sample(self, t):
        return Desired(self.start + self.velocity * t, self.velocity, np.zeros(self.start.size))


@dataclass(frozen=True)
class CircleTrajectory(Trajectory):
    """The first two coordinates go round (center, radius) at omega rad/s; the rest stay 0."""

    n: int
    center: np.ndarray
    radius: float
    omega: float
    phase: float = 0.0

    def sample(self, t):
        q, qd, qdd = np.zeros(self.n), np.zeros(self.n), np.zeros(self.n)
        a = self.omega * t + self.phase
        r, w = self.radius, self.omega
        q[:2] = self.center + r * np.array([math.cos(a), math.sin(a)])
        qd[:2] = r * w * np.array([-math.sin(a), math.cos(a)])
        qdd[:2] = -r * w * w * np.array([math.cos(a), math.sin(a)])
        return Desired(q, qd, qdd)


@dataclass(frozen=True)
class FunctionTrajectory(Trajectory):
    """Any callable t -> (q_d, q̇_d, q̈_d)."""

    function: Callable[[float], tuple]

    def sample(self, t):
        q, qd, qdd = self.function(t)
        return Desired(np.asarray(q, float), np.asarray(qd, float), np.asarray(qdd, float))


# ----- operators -------------------------------------------------------------
@dataclass(frozen=True)
class HumanCommand:
    deflection: np.ndarray   # q̂_h
    force: np.ndarray        # u_h = k_p q̂_h (44)
    intent: float            # v_h (45)


def intent(kp, deflection):
    """v_h = ½ Σ_j k_p,j q̂_h,j² (45): the energy stored in the joystick spring (44).

    On sequences of Python floats (what the controller's policy has from the wire) a loop on
    floats, no array built. On numpy arrays the sum runs over the first axis: a float for
    n-vectors, one v_h per robot for deflections (n, N) with k_p (n, N) or (n, 1) (the batched
    runs).
    """
    if isinstance(deflection, np.ndarray):
        if deflection.ndim == 1:
            return 0.5 * float(np.dot(kp, deflection * deflection))
        return 0.5 * np.sum(kp * (deflection * deflection), axis=0)
    total = 0.0
    for k, d in zip(kp, deflection):
        total += k * d * d
    return 0.5 * total


class HumanModel(ABC):
    kp: np.ndarray
    trajectory: Trajectory

    def desired(self, t: float) -> Desired:
        return self.trajectory.sample(t)

    def command(self, t: float, q: np.ndarray, v: np.ndarray) -> HumanCommand:
        """The operator's deflection, force and intent at time t for the robot state (q, q̇)."""
        return self.command_from(t, self.desired(t), q, v)

    @abstractmethod
    def command_from(self, t: float, desired: Desired, q: np.ndarray, v: np.ndarray) -> HumanCommand:
        """Same as command(), with the wish at t already sampled."""


@dataclass(frozen=True)
class JoystickSpring(HumanModel):
    """(44) as printed: q̂_h = q_d − q, u_h = k_p q̂_h (no damping: never settles on its own)."""

    trajectory: Trajectory
    kp: np.ndarray

    def command_from(self, t, desired, q, v):
        d = desired.q - q
        return HumanCommand(d, self.kp * d, intent(self.kp, d))


@dataclass(frozen=True)
class ScriptedOperator(HumanModel):
    """A damped imitation of (44): q̂_h = (q_d − q) + (k_d/k_p)(q̇_d − q̇), u_h = k_p q̂_h.

    An operator watching the robot leads the handle by the velocity error; with k_d > 0 the
    human-only loop settles on q_d instead of oscillating around it.
    """

    trajectory: Trajectory
    kp: np.ndarray
    kd: np.ndarray

    def command_from(self, t, desired, q, v):
        d = (desired.q - q) + (self.kd / self.kp) * (desired.q_dot - v)
        return HumanCommand(d, self.kp * d, intent(self.kp, d))


@dataclass(frozen=True)
class ArbitraryOperator(HumanModel):
    """Any input: a callable (t, q, v) -> u_h, or a recorded series (times, forces) held between samples.

    The deflection is u_h / k_p so that the intent (45) stays the spring energy.
    """

    trajectory: Trajectory
    kp: np.ndarray
    function: Callable[[float, np.ndarray, np.ndarray], np.ndarray] | None = None
    times: np.ndarray | None = None
    forces: np.ndarray | None = None

    def command_from(self, t, desired, q, v):
        if self.function is not None:
            u = np.asarray(self.function(t, q, v), dtype=float)
        else:
            k = int(np.searchsorted(self.times, t, side="right")) - 1
            u = self.forces[max(k, 0)] if k >= 0 else np.zeros_like(q)
        u = np.where(np.isfinite(u), u, 0.0)
        d = u / self.kp
        return HumanCommand(d, u, intent(self.kp, d))


@dataclass(frozen=True)
class AdversarialOperator(HumanModel):
    """An operator who drives at the obstacle and ignores what the robot does.

    The wish is a fixed `target` (outside the feasible set: the obstacle), and the handle is held
    at full deflection toward it: q̂_h = sat(target − q) with sat clipping each coordinate to
    [−`deflection`, `deflection`]. No damping, no reaction to the machine's pushback or to the
    robot's speed: only the direction to the target is used. The force is u_h = k_p q̂_h (44),
    the intent v_h the spring energy (45), so the sharing function sees a large, persistent v_h.
    """

    trajectory: Trajectory
    kp: np.ndarray
    target: np.ndarray
    deflection: float = 1.0

    def command_from(self, t, desired, q, v):
        d = np.clip(self.target - q, -self.deflection, self.deflection)
        return HumanCommand(d, self.kp * d, intent(self.kp, d))

