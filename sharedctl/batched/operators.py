"""The human models of sharedctl/human.py for a whole batch (paper (44), (45)).

One robot, one operator; the batch holds every operator's parameters as arrays so the
wish (q_d, q̇_d, q̈_d) and the joystick force u_h = k_p q̂_h are computed for all robots by
the same few array operations. Arrays are component-major: shape (n, N).

Supported (the models the scenario files build):

* trajectories: `LineTrajectory` (and its "point" form, velocity 0), `CircleTrajectory`;
* operators: `ScriptedOperator` (q̂_h = (q_d − q) + (k_d/k_p)(q̇_d − q̇)), `JoystickSpring`
  (the same with k_d = 0, i.e. q̂_h = q_d − q), `AdversarialOperator`
  (q̂_h = clip(target − q, ±deflection)).

`ArbitraryOperator` and `FunctionTrajectory` take Python callables per robot and are refused
with a `TypeError`: a callable per robot per RK stage is exactly what a batch must avoid.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Sequence

import numpy as np

from ..human import (
    AdversarialOperator, CircleTrajectory, HumanModel, JoystickSpring, LineTrajectory, ScriptedOperator, intent,
)


@dataclass(frozen=True)
class DesiredBatch:
    """q_d, q̇_d, q̈_d for every robot, each (n, N)."""

    q: np.ndarray
    q_dot: np.ndarray
    q_ddot: np.ndarray


@dataclass(frozen=True)
class OperatorBatch:
    """Every robot's operator and wish. Arrays (n, N) unless noted."""

    kp: np.ndarray
    damping_ratio: np.ndarray      # k_d / k_p (0 for the spring and the adversary)
    adversarial: np.ndarray        # (N,) bool: aims at `target` with a clipped deflection
    target: np.ndarray
    deflection: np.ndarray         # (N,) clip of the adversary's deflection (+inf otherwise)
    circle: np.ndarray             # (N,) bool: circle wish, else line
    line_start: np.ndarray
    line_velocity: np.ndarray
    circle_center: np.ndarray      # (2, N)
    circle_radius: np.ndarray      # (N,)
    circle_omega: np.ndarray       # (N,)
    circle_phase: np.ndarray       # (N,)

    @staticmethod
    def adversaries(kp: np.ndarray, target: np.ndarray, deflection: np.ndarray) -> "OperatorBatch":
        """N adversarial operators (human.AdversarialOperator) given as arrays: k_p and target
        (n, N), deflection (N,); each wish is the point `target`, as the scenario files build it."""
        n, N = target.shape
        zeros, none = np.zeros((n, N)), np.zeros(N, bool)
        return OperatorBatch(np.ascontiguousarray(np.broadcast_to(kp, (n, N)), dtype=float), zeros, np.ones(N, bool),
                             target.astype(float), np.broadcast_to(deflection, (N,)).astype(float), none,
                             target.astype(float), zeros,
                             np.zeros((2, N)), np.zeros(N), np.zeros(N), np.zeros(N))

    @property
    def size(self) -> int:
        return self.kp.shape[1]

    def take(self, index) -> "OperatorBatch":
        """The operators of robots `index` (an index array or slice over the batch)."""
        return OperatorBatch(**{name: np.ascontiguousarray(getattr(self, name)[..., index])
                                for name in self.__dataclass_fields__})

    # ----- the wish ------------------------------------------------------------
    @cached_property
    def _point(self) -> DesiredBatch | None:
        """The wish when every robot's is a point (a line of velocity 0, as an adversary's): then
        q_d(t) = start, q̇_d = q̈_d = 0 at every t, one object (the step computes its projected
        reference once for the three RK stage times)."""
        if self.circle.any() or np.any(self.line_velocity != 0.0):
            return None
        zeros = np.zeros(self.kp.shape)
        return DesiredBatch(self.line_start + zeros, zeros, zeros)

    @cached_property
    def _adversaries(self) -> tuple[bool, bool]:
        """(any, all) robots driven by an adversary."""
        return bool(self.adversarial.any()), bool(self.adversarial.all())

    @cached_property
    def _minus_deflection(self) -> np.ndarray:
        return -self.deflection

    def desired(self, t: float) -> DesiredBatch:
        """q_d(t), q̇_d(t), q̈_d(t) for every robot (human.py's Trajectory.sample, vectorised)."""
        if self._point is not None:
            return self._point
        n, N = self.kp.shape
        any_circle = bool(self.circle.any())
        all_circle = any_circle and bool(self.circle.all())
        if not all_circle:
            line = (self.line_start + self.line_velocity * t, self.line_velocity, np.zeros((n, N)))
            if not any_circle:
                return DesiredBatch(*line)
        a = self.circle_omega * t + self.circle_phase
        r, w = self.circle_radius, self.circle_omega
        cos_a, sin_a = np.cos(a), np.sin(a)
        q, qd, qdd = np.zeros((n, N)), np.zeros((n, N)), np.zeros((n, N))
        q[0] = self.circle_center[0] + r * cos_a
        q[1] = self.circle_center[1] + r * sin_a
        rw = r * w
        qd[0] = rw * -sin_a
        qd[1] = rw * cos_a
        rww = -r * w * w
        qdd[0] = rww * cos_a
        qdd[1] = rww * sin_a
        if all_circle:
            return DesiredBatch(q, qd, qdd)
        c = self.circle
        return DesiredBatch(np.where(c, q, line[0]), np.where(c, qd, line[1]), np.where(c, qdd, line[2]))

    # ----- the handle ----------------------------------------------------------
    def deflection_of(self, desired: DesiredBatch, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """q̂_h for every robot."""
        any_adv, all_adv = self._adversaries
        if not all_adv:
            tracking = (desired.q - q) + self.damping_ratio * (desired.q_dot - v)
            if not any_adv:
                return tracking
        pushing = np.subtract(self.target, q)
        np.maximum(pushing, self._minus_deflection, out=pushing)      # np.clip, faster
        np.minimum(pushing, self.deflection, out=pushing)
        return pushing if all_adv else np.where(self.adversarial, pushing, tracking)

    def command(self, desired: DesiredBatch, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(u_h (n, N), v_h (N,)): the force (44) and the intent (45)."""
        d = self.deflection_of(desired, q, v)
        return self.kp * d, intent(self.kp, d)

    def force(self, desired: DesiredBatch, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        return self.kp * self.deflection_of(desired, q, v)


def operators_from_models(models: Sequence[HumanModel], n: int) -> OperatorBatch:
    """Stack scalar human models (one per robot) into an OperatorBatch."""
    N = len(models)
    kp, ratio = np.zeros((n, N)), np.zeros((n, N))
    adversarial, target, deflection = np.zeros(N, bool), np.zeros((n, N)), np.full(N, np.inf)
    circle = np.zeros(N, bool)
    start, velocity = np.zeros((n, N)), np.zeros((n, N))
    center, radius, omega, phase = np.zeros((2, N)), np.zeros(N), np.zeros(N), np.zeros(N)
    for i, model in enumerate(models):
        kp[:, i] = np.broadcast_to(np.asarray(model.kp, float), (n,))
        if isinstance(model, ScriptedOperator):
            ratio[:, i] = np.broadcast_to(np.asarray(model.kd, float) / np.asarray(model.kp, float), (n,))
        elif isinstance(model, AdversarialOperator):
            adversarial[i] = True
            target[:, i] = model.target
            deflection[i] = model.deflection
        elif not isinstance(model, JoystickSpring):
            raise TypeError(f"robot {i}: {type(model).__name__} cannot be batched (scripted, spring, adversarial only)")
        traj = model.trajectory
        if isinstance(traj, LineTrajectory):
            start[:, i], velocity[:, i] = traj.start, traj.velocity
        elif isinstance(traj, CircleTrajectory):
            if traj.n != n:
                raise ValueError(f"robot {i}: circle trajectory of dimension {traj.n}, expected {n}")
            circle[i] = True
            center[:, i], radius[i], omega[i], phase[i] = traj.center, traj.radius, traj.omega, traj.phase
        else:
            raise TypeError(f"robot {i}: {type(traj).__name__} cannot be batched (line, point, circle only)")
    return OperatorBatch(kp, ratio, adversarial, target, deflection, circle, start, velocity, center, radius, omega,
                         phase)
