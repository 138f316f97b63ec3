"""Backup-safe states (sharedctl/backup.py, docs/control.md §10) against independent oracles.

* the braking distance's closed form against a numerical integral;
* the omnidirectional robot's brake blocks against the plant's own friction and brakes: the least
  deceleration over directions (stopping.worst_coast_model samples them), and the displacement of
  a braked stop measured on the plant (RK4, services/robot/plant.py) within the cone bound;
* the fallback never lowers the state's backup margin (the invariance argument), and govern's
  result is backup-safe whenever it says so;
* in closed loop on the plant: a loss of actuation at any instant of the adversarial wall and of
  random cases ends inside.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sharedctl.backup import BrakeBlock, govern, omni_backup
from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.models import OmniRobot
from sharedctl.services.robot.plant import Plant, RobotSimConfig
from sharedctl.services.scenario_files import load
from sharedctl.services.studies.campaign import stopping
from sharedctl.shared_controller import OperatorInput, SharedController

from . import strategies as S

CONFIG = RobotSimConfig()
MODEL = OmniRobot()
BACKUP = omni_backup(MODEL.parameters, CONFIG.brake_torque, CONFIG.friction_coulomb, CONFIG.friction_viscous,
                     CONFIG.watchdog_timeout)
BOX = FeasibleSet.from_regions([Polytope.from_rows(
    [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], [-1.0, -1.0, -1.0, -1.0, -1.5, -1.5])])


@pytest.mark.parametrize("speed", [0.0, 1e-4, 0.05, 0.5, 1.3, 3.0, 8.0])
def test_the_braking_distance_is_the_integral_of_v_over_the_deceleration(speed):
    block = BrakeBlock((0, 1), 2.54, 0.528)
    assert block.distance(speed) == pytest.approx(S.braking_distance(block, speed), rel=1e-9, abs=1e-15)
    creeping = BrakeBlock((0, 1), 2.54, 0.528, creep=5e-4)
    assert creeping.distance(speed) == pytest.approx(block.distance(speed) + (5e-4 if speed > 0 else 0.0), rel=1e-12)


def test_the_translation_block_has_the_plant_s_least_deceleration_over_directions():
    worst = stopping.worst_coast_model(Plant(MODEL, CONFIG))
    translation = BACKUP.blocks[0]
    assert translation.coulomb == pytest.approx(worst.coulomb, rel=1e-4)
    assert translation.viscous == pytest.approx(worst.viscous, rel=1e-9)


def _braked_path(v0, psi=0.0, psi_dot=0.0, dt=5e-4):
    """Positions of the plant from (0, 0, ψ) at velocity (v0, ψ̇), drives disarmed, brakes on."""
    plant = Plant(MODEL, CONFIG)
    state = plant.initial_state(np.array([0.0, 0.0, psi]), np.array([v0[0], v0[1], psi_dot]))
    brakes = plant.brake_torques((True, True, True))
    path = [state.q.copy()]
    for _ in range(20_000):
        state = plant.step(state, (0.0, 0.0, 0.0), dt, brakes)
        path.append(state.q.copy())
        if np.linalg.norm(state.qd) < 1e-4:
            break
    return np.array(path)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(speed=st.floats(0.05, 3.0), heading=st.floats(-math.pi, math.pi), normal=st.floats(-math.pi, math.pi),
       psi=st.floats(-0.5, 0.5))
def test_a_braked_stop_advances_a_row_no_further_than_the_cone_bound(speed, heading, normal, psi):
    """On the plant: from any speed and heading, at any yaw, the largest advance along any row
    direction n while the brakes stop the robot is at most advance_b(n, v) (s_b(|v|) times the
    best cosine within 30° of v) — the bound the governor and the speed-aware sets rely on."""
    v0 = speed * np.array([math.cos(heading), math.sin(heading)])
    path = _braked_path(v0, psi)
    n = np.array([math.cos(normal), math.sin(normal)])
    measured = float(np.max(path[:, :2] @ n))
    bound = BACKUP.blocks[0].advance([(tuple(n), 1.0)], list(v0))[0]
    assert measured <= bound + 1e-6


def test_a_braked_stop_turns_the_velocity_so_the_cone_is_needed():
    """Not vacuous: heading 15° off a wheel's null direction, the stop drifts sideways — a row
    along the normal to v advances, which a straight-line stop would not allow."""
    v0 = 1.0 * np.array([math.cos(math.radians(15.0)), math.sin(math.radians(15.0))])
    path = _braked_path(v0)
    sideways = np.array([-v0[1], v0[0]])
    drift = max(float(np.max(path[:, :2] @ sideways)), float(np.max(path[:, :2] @ -sideways)))
    assert drift > 1e-3


@settings(max_examples=60, deadline=None, derandomize=True)
@given(x=st.floats(-0.8, 0.8), y=st.floats(-0.8, 0.8), speed=st.floats(0.0, 2.0), heading=st.floats(-math.pi, math.pi),
       yaw_rate=st.floats(-1.0, 1.0))
def test_the_fallback_never_lowers_the_state_s_backup_margin(x, y, speed, heading, yaw_rate):
    """Under u_g (held one period, the model integrated finely) the state's backup margin does not
    decrease: the step of the invariance argument in docs/control.md §10."""
    q = np.array([x, y, 0.0])
    v = np.array([speed * math.cos(heading), speed * math.sin(heading), yaw_rate])
    before = BACKUP.state_margin(BOX, q, v)
    u_g = MODEL.inverse_dynamics(q, v, BACKUP.fallback_acceleration(v))
    q1, v1 = q, v
    h = 0.002 / 20
    for _ in range(20):
        a = MODEL.acceleration(q1, v1, u_g)
        q1, v1 = q1 + h * v1 + 0.5 * h * h * a, v1 + h * a
    assert BACKUP.state_margin(BOX, q1, v1) >= before - 1e-6


@settings(max_examples=60, deadline=None, derandomize=True)
@given(x=st.floats(-0.95, 0.95), speed=st.floats(0.0, 3.0), force=st.floats(-400.0, 400.0))
def test_govern_returns_the_command_when_it_is_safe_and_a_safe_one_when_it_changes_it(x, speed, force):
    q, v, u = np.array([x, 0.0, 0.0]), np.array([speed, 0.0, 0.0]), np.array([force, 0.0, 0.0])
    dt = 0.002
    out = govern(BACKUP, MODEL, BOX, q, v, u, dt)
    a = MODEL.acceleration(q, v, out.u)
    safe = (BACKUP.command_margin(BOX, q, v, a) >= BACKUP.margin
            and BACKUP.state_margin(BOX, q + v * dt + 0.5 * a * dt * dt, v + a * dt) >= BACKUP.margin)
    if out.share == 0.0:
        assert np.array_equal(out.u, u)
    if out.feasible:
        assert safe
    if out.share > 0.0:
        assert out.u[0] < u[0]                       # it only ever brakes harder towards x = 1


def _passes(q, v, u, dt=0.002):
    a = MODEL.acceleration(q, v, u)
    return (BACKUP.command_margin(BOX, q, v, a) >= BACKUP.margin
            and BACKUP.state_margin(BOX, q + v * dt + 0.5 * a * dt * dt, v + a * dt) >= BACKUP.margin)


@settings(max_examples=80, deadline=None, derandomize=True)
@given(x=st.floats(0.2, 0.9), y=st.floats(-0.8, 0.8), speed=st.floats(0.5, 2.5), heading=st.floats(-0.8, 0.8),
       push=st.floats(50.0, 400.0))
def test_govern_changes_the_command_no_more_than_needed(x, y, speed, heading, push):
    """Where the governor moves a push towards the face x = 1, its λ is within 0.005 of the least λ
    on the segment u → u_g that passes (an oracle: 30 halvings of the public margins' test)."""
    q = np.array([x, y, 0.0])
    v = np.array([speed * math.cos(heading), speed * math.sin(heading), 0.0])
    u = np.array([push, 0.0, 0.0])
    out = govern(BACKUP, MODEL, BOX, q, v, u, 0.002)
    if out.share == 0.0 or not out.feasible:
        return
    u_g = MODEL.inverse_dynamics(q, v, BACKUP.fallback_acceleration(v))
    lo, hi = 0.0, 1.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if _passes(q, v, u + mid * (u_g - u)) else (mid, hi)
    assert _passes(q, v, out.u)
    assert out.share - hi <= 0.005


def test_govern_leaves_a_state_outside_the_envelope_to_a_law_braking_harder_than_the_fallback():
    """0.05 m from the face at 3 m/s no stop ends inside: a law braking at 900 N is sent unchanged."""
    q, v, u = np.array([0.95, 0.0, 0.0]), np.array([3.0, 0.0, 0.0]), np.array([-900.0, 0.0, 0.0])
    out = govern(BACKUP, MODEL, BOX, q, v, u, 0.002)
    assert not out.feasible and out.share == 0.0 and np.array_equal(out.u, u)


@pytest.mark.parametrize("push", [0.0, 120.0, 400.0])
def test_govern_sends_the_fallback_outside_the_envelope_when_the_law_does_not_brake_harder(push):
    """0.3 m from the face at 2 m/s no stop ends δ inside; a law still tracking towards the face (or
    coasting) must not go out unchanged: the fallback u_g, which brakes along −v, is sent instead."""
    q, v, u = np.array([0.7, 0.0, 0.0]), np.array([2.0, 0.0, 0.0]), np.array([push, 0.0, 0.0])
    out = govern(BACKUP, MODEL, BOX, q, v, u, 0.002)
    u_g = MODEL.inverse_dynamics(q, v, BACKUP.fallback_acceleration(v))
    assert not out.feasible and out.share == 1.0
    np.testing.assert_allclose(out.u, u_g, rtol=1e-12)
    assert out.u[0] < 0.0


@pytest.mark.parametrize("controller", S.CONTROLLERS)
def test_a_loss_of_actuation_at_any_instant_of_the_adversarial_wall_ends_inside(controller):
    """The controller lost every 0.1 s of the adversarial operator's run (1.3 m/s at the wall):
    last torque held T_w, then the plant's brakes; never outside, with more than 2 cm to spare."""
    scenario = load("adversarial_wall")
    samples, plant, feasible = stopping.sampled_loop(scenario, 4.0, controller)
    margins = [stopping.forecast(samples, plant, feasible, t).min_margin for t in np.arange(0.0, 4.0, 0.1)]
    assert min(margins) > 0.02


def _lost_at(case, controller, instant, period=0.002):
    """The case's loop sampled at 500 Hz on the plant up to `instant`, then the controller lost:
    the smallest margin of the stop (last wheel torques held T_w, then the brakes)."""
    loop = case.loop(controller)
    ctrl = SharedController(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference, loop.backup)
    state = ctrl.initial_state(case.q0, loop.theta_hat0)
    plant = Plant(loop.model, CONFIG)
    ps, tau, smallest = plant.initial_state(case.q0, case.v0), (0.0, 0.0, 0.0), math.inf
    for k in range(int(round(instant / period))):
        t = k * period
        cmd = loop.human.command(t, ps.q, ps.qd)
        state, out = ctrl.step(state, ps.q, None if loop.controller.observer else ps.qd,
                               OperatorInput(loop.human.desired(t), cmd.force, cmd.intent), period)
        tau = tuple(float(x) for x in loop.model.wheel_torques(ps.q, out.u_s))
        for _ in range(2):
            ps = plant.step(ps, tau, period / 2)
            smallest = min(smallest, loop.feasible.margin(ps.q))
    stop, _, _ = stopping.coast(plant, loop.feasible, ps.q, ps.qd, tau, CONFIG.watchdog_timeout)
    return min(smallest, stop)


@settings(max_examples=6, **S.SIM_SETTINGS)
@given(case=st.one_of(S.convex_cases, S.adversarial_cases), instant=st.floats(0.2, 0.95), controller=S.controllers)
def test_a_loss_of_actuation_at_a_random_instant_of_a_random_case_ends_inside(case, instant, controller):
    """Random convex sets and random pushes: the sampled loop on the plant, the controller lost at
    a random point of the run, the stop measured on the plant."""
    assert _lost_at(case, controller, instant * case.duration) > 0.0, (case.label, controller, instant)
