"""Wheel odometry (services/controller/odometry.py) against the omnidirectional robot model."""
import math
import random

import numpy as np
import pytest

from sharedctl.models import OmniRobot
from sharedctl.services.controller.odometry import TWO_PI, AxisEstimate, WheelOdometry, feedback_ages

MODEL = OmniRobot()


def wheel_speeds(q, v):
    """ω = B(ψ)ᵀ q̇ with the printed B(ψ) (`input_matrix`), not the closed form the odometry uses."""
    return MODEL.input_matrix(q).T @ v


def encoder_estimates(q, v, wheel_turns, t):
    """What the drives report for body velocity v at pose q: ω = Bᵀq̇ as turns/s."""
    omega = wheel_speeds(q, v)
    return [AxisEstimate(float(p), float(w / TWO_PI), t) for p, w in zip(wheel_turns, omega)]


@pytest.mark.parametrize("psi", [0.0, 0.7, -2.0])
def test_wheel_speeds_of_a_known_body_velocity_give_it_back(psi):
    q, v = np.array([0.3, -0.2, psi]), np.array([0.4, -0.25, 0.8])
    odo = WheelOdometry(MODEL, q)
    _, v_est = odo.update(encoder_estimates(q, v, np.zeros(3), 0.0))
    np.testing.assert_allclose(v_est, v, atol=1e-12)


def test_pose_stays_at_the_initial_q_until_every_wheel_has_reported():
    q0 = np.array([-0.9, 3.0, 0.0])
    odo = WheelOdometry(MODEL, q0)
    est = encoder_estimates(q0, np.array([1.0, 0.0, 0.0]), np.zeros(3), 0.0)
    q, v = odo.update([est[0], None, est[2]])
    np.testing.assert_array_equal(q, q0)
    np.testing.assert_array_equal(v, np.zeros(3))


def drive_circle(source, steps=2000, dt=0.002):
    """The robot goes round a circle of radius R while turning; return (odometry q, true q)."""
    R, w, yaw_rate = 0.5, math.pi / 2, 0.4
    def truth(t):
        return np.array([R * math.cos(w * t), R * math.sin(w * t), yaw_rate * t])
    def velocity(t):
        return np.array([-R * w * math.sin(w * t), R * w * math.cos(w * t), yaw_rate])
    # wheel angles: φ(t) = ∫ Bᵀ(ψ(s)) q̇(s) ds, integrated finely
    fine = 20
    odo = WheelOdometry(MODEL, truth(0.0), source=source)
    phi = np.zeros(3)
    h = dt / fine
    for k in range(steps + 1):
        t = k * dt
        odo.update(encoder_estimates(truth(t), velocity(t), phi / TWO_PI, t))
        for j in range(fine):  # midpoint rule for the next dt
            s = t + (j + 0.5) * h
            phi += h * wheel_speeds(truth(s), velocity(s))
    return odo.q, truth(steps * dt)


def test_pose_from_wheel_angles_follows_a_circle():
    q, q_true = drive_circle("position")
    np.testing.assert_allclose(q, q_true, atol=1e-6)


def test_pose_from_trapezoidal_velocity_integration_follows_a_circle():
    q, q_true = drive_circle("velocity")
    np.testing.assert_allclose(q, q_true, atol=1e-4)


def test_feedback_age_is_per_axis_and_infinite_before_any_estimate():
    ests = [AxisEstimate(0.0, 0.0, 1.0), None, AxisEstimate(0.0, 0.0, 1.04)]
    ages = feedback_ages(ests, 1.05)
    assert ages[0] == pytest.approx(0.05)
    assert math.isinf(ages[1])
    assert ages[2] == pytest.approx(0.01)


def test_a_wheel_position_jump_is_a_discontinuity_not_a_motion():
    q0 = np.array([-0.9, 3.0, 0.0])
    odo = WheelOdometry(MODEL, q0)
    odo.update(encoder_estimates(q0, np.zeros(3), np.array([500.0, 500.0, 500.0]), 0.0))
    q, _ = odo.update(encoder_estimates(q0, np.zeros(3), np.zeros(3), 0.002))   # drive restarted at 0 turns
    np.testing.assert_array_equal(q, q0)
    assert odo.discontinuities == 1


class SolvedWheelMap:
    """q̇ = B(ψ)⁻ᵀ ω by a numpy solve of the printed B(ψ): a reference for the closed form."""

    def body_velocity(self, q, w):
        v = np.linalg.solve(MODEL.input_matrix(np.array(q)).T, np.array(w))
        return float(v[0]), float(v[1]), float(v[2])


@pytest.mark.parametrize("source", ["position", "velocity"])
def test_odometry_on_the_closed_form_equals_the_odometry_on_numpy_solves(source):
    """Random wheel motion (with a drive restart in the middle): both pose and velocity agree to rounding."""
    rng = random.Random(5)
    fast = WheelOdometry(MODEL, np.array([-0.9, 3.0, 0.4]), source=source)
    reference = WheelOdometry(MODEL, np.array([-0.9, 3.0, 0.4]), source=source)
    reference.wheel_map = SolvedWheelMap()
    pos, t = [0.0, 0.0, 0.0], 0.0
    for k in range(1500):
        vel = [1.0 + rng.uniform(-3, 3) for _ in range(3)]      # equal wheel speeds turn the robot
        pos = [p + v * 0.002 for p, v in zip(pos, vel)]
        if k == 700:
            pos = [p + 5.0 for p in pos]               # a jump of 5 turns (a drive reset): a discontinuity
        t += 0.002
        estimates = [AxisEstimate(p, v, t) for p, v in zip(pos, vel)]
        q_fast, v_fast = fast.update(estimates)
        q_ref, v_ref = reference.update(estimates)
        np.testing.assert_allclose(q_fast, q_ref, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(v_fast, v_ref, rtol=1e-12, atol=1e-12)
    assert fast.discontinuities == reference.discontinuities == 1
    assert abs(fast.q[2] - 0.4) > 0.01                          # the pose did move
