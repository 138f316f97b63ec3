"""The omni robot's wheel map in closed form (`OmniRobot.wheel_map`, `sharedctl/models/omni_robot.py`)
against numpy solves of the printed input matrix B(ψ) (`OmniRobot.input_matrix`) and values computed
by hand."""
import math
import random
import warnings

import numpy as np
import pytest

from sharedctl.models import OmniRobot
from sharedctl.models.omni_robot import OmniRobotParameters

MODEL = OmniRobot()
OTHER = OmniRobot(OmniRobotParameters(wheel_radius=0.05, wheel_distance=0.3, delta=-0.4))
R, L = MODEL.parameters.wheel_radius, MODEL.parameters.wheel_distance


def cases(n=300, seed=7):
    rng = random.Random(seed)
    for _ in range(n):
        q = [rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-20, 20)]
        yield q, [rng.uniform(-50, 50) for _ in range(3)]


def printed_b(model, q):
    return model.input_matrix(np.array(q))


@pytest.mark.parametrize("model", [MODEL, OTHER], ids=["paper", "other_geometry"])
def test_wheel_torques_equal_the_numpy_solve_of_b(model):
    for q, u in cases(seed=11):
        expected = np.linalg.solve(printed_b(model, q), u)
        np.testing.assert_allclose(model.wheel_map.wheel_torques(q, u), expected, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(model.wheel_torques(np.array(q), np.array(u)), expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("model", [MODEL, OTHER], ids=["paper", "other_geometry"])
def test_body_velocity_equals_the_numpy_solve_of_b_transpose(model):
    for q, w in cases():
        expected = np.linalg.solve(printed_b(model, q).T, w)
        np.testing.assert_allclose(model.wheel_map.body_velocity(q, w), expected, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(model.body_velocity_from_wheels(np.array(q), np.array(w)), expected, rtol=1e-12,
                                   atol=1e-12)


@pytest.mark.parametrize("model", [MODEL, OTHER], ids=["paper", "other_geometry"])
def test_wheel_speeds_equal_b_transpose_times_the_velocity(model):
    for q, v in cases(seed=3):
        expected = printed_b(model, q).T @ v
        np.testing.assert_allclose(model.wheel_map.wheel_speeds(q, v), expected, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(model.wheel_speeds(np.array(q), np.array(v)), expected, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("model", [MODEL, OTHER], ids=["paper", "other_geometry"])
def test_generalised_force_equals_b_times_the_wheel_torques(model):
    for q, tau in cases(seed=5):
        expected = printed_b(model, q) @ tau
        np.testing.assert_allclose(model.wheel_map.generalised_force(q, tau), expected, rtol=1e-12, atol=1e-9)


def test_a_world_x_force_at_quarter_turn_is_a_push_by_wheels_0_and_1():
    """ψ = π/2, u = (1, 0, 0): the force is −y in the body frame; with δ = π/6 wheel 2 (drive along body x)
    gives nothing and τ_0 = −τ_1 = −r/√3 (by hand: u_x = −(sin 120°·τ_0 + sin(−60°)·τ_1)/r = 1)."""
    tau = MODEL.wheel_map.wheel_torques([0.0, 0.0, math.pi / 2], [1.0, 0.0, 0.0])
    assert tau == pytest.approx((-R / math.sqrt(3.0), R / math.sqrt(3.0), 0.0), abs=1e-15)


def test_a_pure_torque_about_z_is_shared_equally_by_the_wheels():
    """u = (0, 0, u_ψ) at any yaw: u_ψ = (L_r/r) Σ τ_j, and by symmetry τ_j = r u_ψ / (3 L_r)."""
    tau = MODEL.wheel_map.wheel_torques([0.4, -1.0, 2.3], [0.0, 0.0, 3.0])
    assert tau == pytest.approx((R / L,) * 3, rel=1e-12)


def test_equal_wheel_speeds_turn_the_robot_on_the_spot():
    """ω_j = ω for every wheel: the robot spins about its centre with ψ̇ = r ω / L_r."""
    v = MODEL.wheel_map.body_velocity([1.0, 2.0, -0.8], [5.0, 5.0, 5.0])
    assert v == pytest.approx((0.0, 0.0, R * 5.0 / L), abs=1e-12)


def test_torques_to_force_and_back_is_the_identity():
    wheel_map = OTHER.wheel_map
    for q, tau in cases(100, seed=13):
        back = wheel_map.wheel_torques(q, wheel_map.generalised_force(q, tau))
        np.testing.assert_allclose(back, tau, rtol=1e-12, atol=1e-12)


def test_the_float_methods_return_float_tuples_and_the_model_methods_arrays():
    q, u = [0.1, 0.2, 0.3], [1.0, 2.0, 3.0]
    tau = MODEL.wheel_map.wheel_torques(q, u)
    assert isinstance(tau, tuple) and all(type(t) is float for t in tau)
    out = MODEL.wheel_torques(np.array(q), np.array(u))
    assert isinstance(out, np.ndarray) and out.shape == (3,)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_yaw_gives_nan_torques_not_an_exception(bad):
    q, u = [0.0, 0.0, bad], [1.0, 2.0, 3.0]
    assert all(math.isnan(t) for t in MODEL.wheel_map.wheel_torques(q, u))
    assert np.all(np.isnan(MODEL.wheel_torques(np.array(q), np.array(u))))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_yaw_gives_nan_wherever_the_yaw_enters(bad):
    """Every wheel speed, and the x, y components of q̇ and u; the ψ row of B does not turn with ψ."""
    wheel_map, q, x = MODEL.wheel_map, [0.0, 0.0, bad], [1.0, 2.0, 3.0]
    assert all(math.isnan(w) for w in wheel_map.wheel_speeds(q, x))
    for name in ("body_velocity", "generalised_force"):
        vx, vy, turn = getattr(wheel_map, name)(q, x)
        assert math.isnan(vx) and math.isnan(vy) and math.isfinite(turn), name


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_input_gives_non_finite_components_not_an_exception(bad):
    q, x = [0.0, 0.0, 0.3], [bad, 2.0, 3.0]
    for name in ("wheel_torques", "body_velocity", "wheel_speeds", "generalised_force"):
        assert not all(math.isfinite(c) for c in getattr(MODEL.wheel_map, name)(q, x)), name
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # the numpy-facing methods are quiet about it too
        assert not np.all(np.isfinite(MODEL.wheel_torques(np.array(q), np.array(x))))
        assert not np.all(np.isfinite(MODEL.body_velocity_from_wheels(np.array(q), np.array(x))))


SINGULAR = [OmniRobotParameters(delta=-math.pi / 2), OmniRobotParameters(wheel_distance=0.0)]


@pytest.mark.parametrize("parameters", SINGULAR, ids=["drives_parallel", "wheels_at_the_centre"])
def test_a_geometry_with_a_singular_b_is_refused(parameters):
    with pytest.raises(ValueError, match="singular"):
        OmniRobot(parameters)
