"""Wheel odometry (services/controller/odometry.py) against the omnidirectional robot model."""
import math

import numpy as np
import pytest

from sharedctl.models import OmniRobot
from sharedctl.services.controller.odometry import TWO_PI, AxisEstimate, WheelOdometry, feedback_ages

MODEL = OmniRobot()


def encoder_estimates(q, v, wheel_turns, t):
    """What the drives report for body velocity v at pose q: ω = Bᵀq̇ as turns/s."""
    omega = MODEL.wheel_speeds(q, v)
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
            phi += h * MODEL.wheel_speeds(truth(s), velocity(s))
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
