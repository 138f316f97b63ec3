"""The robot's true dynamics: the paper's omni3 model plus wheel friction and drive limits."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sharedctl.models import OmniRobot
from sharedctl.services.robot.plant import Plant, RobotSimConfig, RobotSimConfigError

DT = 1e-3
FRICTIONLESS = RobotSimConfig(friction_viscous=0.0, friction_coulomb=0.0)


def run(plant, state, tau, seconds, dt=DT):
    for _ in range(int(round(seconds / dt))):
        state = plant.step(state, tau, dt)
    return state


def reference_rk4(model, q, qd, tau, dt):
    """RK4 of the core model q̈ = M⁻¹(B(ψ)τ − C q̇), no friction."""
    def f(q, v):
        return v, model.acceleration(q, v, model.input_matrix(q) @ tau)
    k1 = f(q, qd)
    k2 = f(q + dt / 2 * k1[0], qd + dt / 2 * k1[1])
    k3 = f(q + dt / 2 * k2[0], qd + dt / 2 * k2[1])
    k4 = f(q + dt * k3[0], qd + dt * k3[1])
    return (q + dt / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]),
            qd + dt / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]))


def test_without_friction_the_plant_matches_the_core_omni_robot_model():
    model = OmniRobot()
    plant = Plant(model, FRICTIONLESS)
    tau = np.array([0.3, -0.2, 0.5])
    state = plant.initial_state([-0.9, 3.0, 0.2], [0.1, -0.2, 0.4])
    q, qd = state.q.copy(), state.qd.copy()
    for _ in range(500):
        state = plant.step(state, tau, DT)
        q, qd = reference_rk4(model, q, qd, tau, DT)
    np.testing.assert_allclose(state.q, q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(state.qd, qd, rtol=0, atol=1e-12)


def test_wheel_speeds_are_b_transpose_qdot():
    model = OmniRobot()
    plant = Plant(model)
    state = plant.initial_state([0.0, 0.0, 0.7], [0.3, -0.1, 0.9])
    np.testing.assert_allclose(plant.wheel_speeds(state), model.input_matrix(state.q).T @ state.qd, atol=1e-12)


def test_wheel_turns_integrate_wheel_speed_over_two_pi():
    model = OmniRobot()
    plant = Plant(model, FRICTIONLESS)
    w = 1.0                                       # pure rotation: every wheel at L·ψ̇/r
    state = run(plant, plant.initial_state([0, 0, 0], [0, 0, w]), np.zeros(3), 1.0)
    p = model.parameters
    np.testing.assert_allclose(state.wheel_turns, np.full(3, p.wheel_distance * w / p.wheel_radius / (2 * math.pi)),
                               rtol=1e-9)


def test_friction_brings_a_coasting_robot_to_rest():
    plant = Plant(OmniRobot())
    state = run(plant, plant.initial_state([0, 0, 0], [0.5, -0.3, 1.0]), np.zeros(3), 3.0)
    assert np.max(np.abs(plant.wheel_speeds(state))) < 1e-3
    assert np.max(np.abs(state.qd)) < 1e-4


def test_friction_never_adds_energy_while_coasting():
    plant = Plant(OmniRobot())
    state = plant.initial_state([0, 0, 0], [0.4, 0.2, -0.6])
    energies = []
    for _ in range(1000):
        state = plant.step(state, np.zeros(3), DT)
        energies.append(plant.kinetic_energy(state))
    assert all(b <= a + 1e-12 for a, b in zip(energies, energies[1:]))


def test_engaged_brakes_stop_the_robot_from_1_m_s_within_0_3_m_and_never_add_energy():
    plant = Plant(OmniRobot())
    brakes = plant.brake_torques((True, True, True))
    state = plant.initial_state([0, 0, 0], [0.0, 1.0, 0.0])
    energies, y0 = [], float(state.q[1])
    for _ in range(1000):
        state = plant.step(state, np.zeros(3), DT, brakes)
        energies.append(plant.kinetic_energy(state))
    assert all(b <= a + 1e-12 for a, b in zip(energies, energies[1:]))
    assert np.max(np.abs(state.qd)) < 1e-3
    assert 0.1 < float(state.q[1]) - y0 < 0.3          # friction alone: about 1.2 m


def test_a_robot_without_brakes_has_no_brake_torque():
    assert Plant(OmniRobot(), RobotSimConfig(brake_torque=0.0)).brake_torques((True, True, True)) == (0.0, 0.0, 0.0)
    assert Plant(OmniRobot()).brake_torques((False, True, False)) == (0.0, 1.0, 0.0)


def test_without_friction_kinetic_energy_grows_by_the_work_of_the_wheel_torques():
    plant = Plant(OmniRobot(), FRICTIONLESS)
    tau = np.array([0.2, 0.1, -0.3])
    state = plant.initial_state([0, 0, 0], [0, 0, 0])
    work = 0.0
    for _ in range(1000):
        w0 = np.array(plant.wheel_speeds(state))
        state = plant.step(state, tau, DT)
        work += 0.5 * DT * tau @ (w0 + np.array(plant.wheel_speeds(state)))   # ∫ τᵀω dt (trapezoid)
    assert plant.kinetic_energy(state) == pytest.approx(work, rel=1e-5)


def test_commanded_torque_is_clamped_to_the_torque_limit():
    plant = Plant(OmniRobot(), RobotSimConfig(torque_limit=2.0))
    assert plant.drive_torque([5.0, -5.0, 1.0], (0.0, 0.0, 0.0)) == (2.0, -2.0, 1.0)
    s0 = plant.initial_state([0, 0, 0], [0, 0, 0])
    np.testing.assert_array_equal(plant.step(s0, [5.0, -5.0, 1.0], DT).qd, plant.step(s0, [2.0, -2.0, 1.0], DT).qd)


def test_beyond_the_wheel_speed_limit_the_drive_gives_no_accelerating_torque():
    plant = Plant(OmniRobot(), RobotSimConfig(wheel_speed_limit=10.0))
    assert plant.drive_torque([1.0, 1.0, -1.0], (11.0, -11.0, 11.0)) == (0.0, 1.0, -1.0)


def test_wheel_speed_saturates_near_the_speed_limit_under_full_torque():
    plant = Plant(OmniRobot(), RobotSimConfig(wheel_speed_limit=20.0, friction_viscous=0.0, friction_coulomb=0.0))
    state = run(plant, plant.initial_state([0, 0, 0], [0, 0, 0]), np.array([1.0, 1.0, 1.0]), 1.0)
    assert max(abs(w) for w in plant.wheel_speeds(state)) < 20.5


def test_non_finite_torque_never_reaches_the_physics():
    plant = Plant(OmniRobot())
    with pytest.raises(AssertionError):
        plant.step(plant.initial_state([0, 0, 0], [0, 0, 0]), [math.nan, 0.0, 0.0], DT)


def test_robot_sim_config_defaults_and_overrides():
    assert RobotSimConfig.from_table(None) == RobotSimConfig()
    config = RobotSimConfig.from_table({"friction_viscous": 0.1, "physics_rate_hz": 2000})
    assert config.friction_viscous == 0.1 and config.physics_rate_hz == 2000.0


@pytest.mark.parametrize("table, key", [
    ({"friction_visc": 0.1}, "robot_sim.friction_visc"),
    ({"torque_limit": -1.0}, "robot_sim.torque_limit"),
    ({"torque_limit": True}, "robot_sim.torque_limit"),
    ({"watchdog_timeout": "0.1"}, "robot_sim.watchdog_timeout"),
    ({"friction_coulomb": -0.1}, "robot_sim.friction_coulomb"),
    ({"encoder_rate_hz": 5000}, "robot_sim.encoder_rate_hz"),
])
def test_robot_sim_config_errors_name_the_key(table, key):
    with pytest.raises(RobotSimConfigError, match=key.replace(".", r"\.")):
        RobotSimConfig.from_table(table)
