"""The omni robot's wheel map in closed form (services/controller/wheel_kinematics.py) against the
model's own numpy solves, and the odometry built on it against the same odometry on those solves."""
import math
import random
from dataclasses import dataclass

import numpy as np
import pytest

from sharedctl.models import OmniRobot
from sharedctl.models.omni_robot import OmniRobotParameters
from sharedctl.services.controller.odometry import AxisEstimate, WheelOdometry
from sharedctl.services.controller.wheel_kinematics import ModelKinematics, WheelKinematics

MODEL = OmniRobot()


def cases(n=300, seed=7):
    rng = random.Random(seed)
    for _ in range(n):
        q = [rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-20, 20)]
        yield q, [rng.uniform(-50, 50) for _ in range(3)]


def test_the_omni_robot_gets_the_closed_form():
    assert isinstance(WheelKinematics.for_model(MODEL), WheelKinematics)


def test_body_velocity_equals_the_numpy_solve_of_b_transpose():
    kin = WheelKinematics.for_model(MODEL)
    for q, w in cases():
        expected = MODEL.body_velocity_from_wheels(np.array(q), np.array(w))
        np.testing.assert_allclose(kin.body_velocity(q, w), expected, rtol=1e-12, atol=1e-12)


def test_wheel_torques_equal_the_numpy_solve_of_b():
    kin = WheelKinematics.for_model(MODEL)
    for q, u in cases(seed=11):
        expected = MODEL.wheel_torques(np.array(q), np.array(u))
        np.testing.assert_allclose(kin.wheel_torques(q, u), expected, rtol=1e-12, atol=1e-12)


def test_other_wheel_geometries_are_checked_too():
    model = OmniRobot(OmniRobotParameters(wheel_radius=0.05, wheel_distance=0.3, delta=0.4))
    kin = WheelKinematics.for_model(model)
    assert isinstance(kin, WheelKinematics)
    for q, u in cases(50, seed=3):
        np.testing.assert_allclose(kin.wheel_torques(q, u), model.wheel_torques(np.array(q), np.array(u)), rtol=1e-12,
                                   atol=1e-12)


@dataclass(frozen=True)
class SkewedRobot(OmniRobot):
    """An input matrix that does not turn with the yaw as a rigid body: no closed form."""

    def input_matrix(self, q):
        b = super().input_matrix(q)
        b[2, 0] += 0.5 * math.sin(q[2])
        return b


def test_a_model_that_does_not_factor_falls_back_to_its_own_solves():
    model = SkewedRobot()
    kin = WheelKinematics.for_model(model)
    assert isinstance(kin, ModelKinematics)
    q, w = [0.1, 0.2, 0.9], [1.0, -2.0, 0.5]
    np.testing.assert_allclose(kin.body_velocity(q, w), model.body_velocity_from_wheels(np.array(q), np.array(w)))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_yaw_or_input_gives_nan_not_an_exception(bad):
    kin = WheelKinematics.for_model(MODEL)
    assert all(math.isnan(t) for t in kin.wheel_torques([0.0, 0.0, bad], [1.0, 2.0, 3.0]))
    assert any(not math.isfinite(t) for t in kin.wheel_torques([0.0, 0.0, 0.3], [bad, 2.0, 3.0]))


@pytest.mark.parametrize("source", ["position", "velocity"])
def test_closed_form_odometry_equals_the_odometry_on_numpy_solves(source):
    """Random wheel motion (with a drive restart in the middle): both pose and velocity agree to rounding."""
    rng = random.Random(5)
    fast = WheelOdometry(MODEL, np.array([-0.9, 3.0, 0.4]), source=source)
    reference = WheelOdometry(MODEL, np.array([-0.9, 3.0, 0.4]), source=source)
    reference.kinematics = ModelKinematics(MODEL)               # the numpy solves of B(ψ)ᵀ
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
