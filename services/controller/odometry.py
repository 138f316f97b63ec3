"""Wheel odometry: pose and velocity of the omnidirectional robot from its wheel encoders.

Pure: encoder estimates and their reception times in, (q, q̇) out; no clock, no bus.

The encoders report wheel position (turns) and speed (turns/s), positive in the direction
of positive ω_j (docs/services.md, "Units"). With ω = 2π·vel (rad/s) the body velocity is
q̇ = B(ψ)⁻ᵀ ω (the model's `WheelMap.body_velocity`, in closed form on Python floats).
The pose is integrated from the scenario's initial q with the wheel *angle increments*
Δφ = 2π·Δpos between two updates, Δq = B(ψ_mid)⁻ᵀ Δφ at the mid-step yaw. That is the
trapezoidal rule for q̇ = B(ψ)⁻ᵀ φ̇ without needing a time base: a late or jittered update
loses no distance, and the controller's clock and the drive's clock never have to agree.
(`source="velocity"` integrates q̇ with the trapezoidal rule over the measured time step
instead, for drives that report no position.)

A drive that restarts counts its encoder from a new origin (0 turns on an incremental encoder).
The plausibility check (encoder_check.py) drops the first readings of such a jump and then takes
the new origin, marking the estimate with a new `epoch`. Across an epoch change the position
increment means nothing: the wheel's travel over the gap is taken from its speeds instead,
½(v_before + v_after)·gap, and the most it could be off — max(|v_before|, |v_after|)·gap of
wheel travel, valid while the robot is braked over the gap (the controller Estops within its
feedback timeout of a drive falling silent or leaving closed loop) — adds to `uncertainty` (m).
A jump of more than `max_step_turns` between two updates is a discontinuity too (all wheels
re-baselined, the pose kept).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sharedctl.models.omni_robot import OmniRobot, WheelMap

TWO_PI = 2.0 * math.pi


@dataclass
class AxisEstimate:
    """The latest encoder estimate of one wheel: turns, turns/s and when it arrived (s); `epoch` counts the
    encoder's new origins (encoder_check.py: a jump that persisted, e.g. a drive that restarted)."""

    pos_turns: float
    vel_turns_s: float
    received: float
    epoch: int = 0


@dataclass
class WheelOdometry:
    """Dead reckoning q, q̇ for an `OmniRobot` from the estimates of its wheels (in node order).

    Call `update(estimates)` once per control period with the latest estimate of every wheel
    (None for a wheel not heard from yet). The pose starts integrating once every wheel has
    reported; until then it stays at the initial q.
    """

    model: OmniRobot
    q0: np.ndarray
    source: str = "position"           # "position" (angle increments) or "velocity" (trapezoid on q̇)
    max_step_turns: float = 2.0        # a larger wheel increment between updates is a discontinuity (drive reset)
    discontinuities: int = field(init=False, default=0)
    uncertainty: float = field(init=False, default=0.0)   # m of wheel travel the pose may have missed
    q: np.ndarray = field(init=False)
    v: np.ndarray = field(init=False)
    updates: int = field(init=False, default=0)
    wheel_map: WheelMap = field(init=False, repr=False)   # the model's B(ψ) in closed form
    _last_pos: list | None = field(init=False, default=None)
    _last_time: float | None = field(init=False, default=None)
    _last_axes: list | None = field(init=False, default=None)    # (epoch, vel, received) per wheel

    def __post_init__(self) -> None:
        if self.source not in ("position", "velocity"):
            raise ValueError(f"odometry source must be 'position' or 'velocity', got {self.source!r}")
        self.q = np.asarray(self.q0, dtype=float).copy()
        self.v = np.zeros_like(self.q)
        self.wheel_map = self.model.wheel_map

    def wheel_speeds(self, estimates) -> np.ndarray:
        """ω (rad/s) = 2π · vel (turns/s)."""
        return TWO_PI * np.array([e.vel_turns_s for e in estimates], dtype=float)

    def update(self, estimates) -> tuple[np.ndarray, np.ndarray]:
        """Advance with the latest estimates; returns (q, q̇) (copies).

        Works on Python floats (three components; `WheelMap`): at 500 Hz a handful of
        numpy calls on 3-vectors cost more than the arithmetic."""
        if any(e is None for e in estimates):
            return self.q.copy(), self.v.copy()
        pos = [e.pos_turns for e in estimates]
        newest = max(e.received for e in estimates)
        omega = [TWO_PI * e.vel_turns_s for e in estimates]
        q = self.q.tolist()
        v_new = self.wheel_map.body_velocity(q, omega)
        last = self._last_pos
        axes = [(e.epoch, e.vel_turns_s, e.received) for e in estimates]
        if last is not None and self._last_axes is not None and any(
                a[0] != b[0] for a, b in zip(axes, self._last_axes)):
            last = self._new_origins(pos, last, axes)
        self._last_axes = axes
        if last is not None and any(abs(p - p0) > self.max_step_turns for p, p0 in zip(pos, last)):
            self.discontinuities += 1       # e.g. a drive restarted from 0 turns: re-baseline, keep the pose
            last = None
        if last is not None:
            if self.source == "position":
                q = self._integrate_angles(q, [TWO_PI * (p - p0) for p, p0 in zip(pos, last)])
            else:
                dt = 0.0 if self._last_time is None else max(newest - self._last_time, 0.0)
                q = [qi + 0.5 * dt * (vi + wi) for qi, vi, wi in zip(q, self.v.tolist(), v_new)]
            v_new = self.wheel_map.body_velocity(q, omega)
            self.q = np.array(q)
        self._last_pos, self._last_time = pos, newest
        self.v = np.array(v_new)
        self.updates += 1
        return self.q.copy(), self.v.copy()

    def _new_origins(self, pos: list, last: list, axes: list) -> list:
        """The baseline with each wheel whose encoder took a new origin moved so that its increment is the
        speed-based travel over the gap; the bound on that guess goes into `uncertainty`."""
        last = list(last)
        radius = self.model.parameters.wheel_radius
        for j, ((epoch, v1, t1), (epoch0, v0, t0)) in enumerate(zip(axes, self._last_axes)):
            if epoch != epoch0:
                gap = max(t1 - t0, 0.0)
                last[j] = pos[j] - 0.5 * (v0 + v1) * gap
                self.uncertainty += TWO_PI * radius * max(abs(v0), abs(v1)) * gap
                self.discontinuities += 1
        return last

    def resume(self, q, turns) -> None:
        """Continue from pose `q`, known to belong to the encoder readings `turns` (a checkpoint's pair, or the
        readings when the pose was declared): the next `update` integrates the increments from `turns` on."""
        self.q = np.asarray(q, dtype=float).copy()
        self.v = np.zeros_like(self.q)
        self._last_pos = [float(t) for t in turns]
        self._last_axes = None          # a new process's epochs start afresh

    def baseline(self) -> tuple[list, list] | None:
        """(q, turns): the pose and the encoder readings it was integrated up to (None before any update)."""
        if self._last_pos is None:
            return None
        return self.q.tolist(), list(self._last_pos)

    def _integrate_angles(self, q: list, d_phi: list) -> list:
        """Δq = B(ψ_mid)⁻ᵀ Δφ: one predictor pass for the yaw, then the midpoint."""
        dq = self.wheel_map.body_velocity(q, d_phi)
        mid = [qi + 0.5 * di for qi, di in zip(q, dq)]
        dq = self.wheel_map.body_velocity(mid, d_phi)
        return [qi + di for qi, di in zip(q, dq)]


def feedback_ages(estimates, now: float) -> np.ndarray:
    """Age (s) of each wheel's latest estimate; +inf for a wheel never heard from."""
    return np.array([math.inf if e is None else max(now - e.received, 0.0) for e in estimates], dtype=float)


def oldest_feedback_age(estimates, now: float) -> float:
    """The largest of `feedback_ages` (s), on Python floats; +inf if a wheel was never heard from."""
    oldest = 0.0
    for e in estimates:
        if e is None:
            return math.inf
        age = now - e.received
        if age > oldest:
            oldest = age
    return oldest
