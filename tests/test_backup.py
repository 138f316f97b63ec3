"""Backup-safe states (sharedctl/backup.py, docs/control.md §10) against independent oracles.

* the braking distance's closed form against a numerical integral;
* the omnidirectional robot's brake blocks against the plant's own wheels: the brakes' least power
  over translations and turns (the plant's wheel map, sampled), and the displacement and the turn of
  braked stops — translating, turning, both — measured on the plant (RK4, services/robot/plant.py)
  within the energy bound, for rows in the plane and rows on the yaw;
* the held wheel torques' departure from constant acceleration against RK4 of the plant without
  friction (the force turns with the robot);
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

from sharedctl.backup import _LAMBDA_RESOLUTION, BrakeBlock, _root, govern, omni_backup
from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.models import OmniRobot
from sharedctl.scenario import parse
from sharedctl.services.robot.plant import Plant, RobotSimConfig
from sharedctl.services.scenario_files import load
from sharedctl.services.studies.campaign import stopping
from sharedctl.shared_controller import OperatorInput, SharedController
from sharedctl.sharing import Authority
from sharedctl.simulator import simulate

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


def _least_brake_power(angle_count=720, turn_count=2001):
    """The plant's least brake power c Σ_j |ω_j| (c = friction + brake per wheel; ω from the plant's own
    wheel map) over unit translations with any yaw rate, and over unit yaw rates with any translation,
    on a grid of headings and rates (W per unit speed)."""
    plant, c = Plant(MODEL, CONFIG), CONFIG.friction_coulomb + CONFIG.brake_torque
    L = MODEL.parameters.wheel_distance

    def power(v):
        return c * sum(abs(w) for w in plant.wheel_speeds(plant.initial_state(np.zeros(3), v)))

    headings = np.linspace(0.0, 2.0 * math.pi, angle_count, endpoint=False)
    turns = np.linspace(-2.0 / L, 2.0 / L, turn_count)
    translation = min(power([math.cos(h), math.sin(h), w]) for h in headings for w in turns)
    yaw = min(power([x, 0.0, 1.0]) for x in np.linspace(-2.0, 2.0, turn_count))
    return translation, yaw


def test_the_blocks_decelerate_at_the_plant_s_least_brake_power_over_translations_and_turns():
    """K̇ ≤ −(brake power): the least power per unit translation speed, over every heading and yaw
    rate, is 1.5c/r (not the √3c/r of a robot that does not turn), and per unit yaw rate 3cL/r; the
    blocks' a_c are those over m1 and m3."""
    m1, m3, _ = MODEL.theta
    translation, yaw = _least_brake_power()
    assert BACKUP.blocks[0].coulomb == pytest.approx(translation / m1, rel=2e-3)
    assert BACKUP.blocks[1].coulomb == pytest.approx(yaw / m3, rel=2e-3)
    not_turning = stopping.worst_coast_model(Plant(MODEL, CONFIG))
    assert BACKUP.blocks[0].coulomb < 0.9 * not_turning.coulomb


def _braked_path(v0, psi=0.0, psi_dot=0.0, dt=5e-4):
    """Positions of the plant from (0, 0, ψ) at velocity (v0, ψ̇), drives disarmed, brakes on."""
    plant = Plant(MODEL, CONFIG)
    state = plant.initial_state(np.array([0.0, 0.0, psi]), np.array([v0[0], v0[1], psi_dot]))
    brakes = plant.brake_torques((True, True, True))
    path = [state.q.copy()]
    for _ in range(40_000):
        state = plant.step(state, (0.0, 0.0, 0.0), dt, brakes)
        path.append(state.q.copy())
        if np.linalg.norm(state.qd) < 1e-4:
            break
    return np.array(path)


#: the stop at once (T_w = 0): its state reach is the braked path alone
BRAKES = omni_backup(MODEL.parameters, CONFIG.brake_torque, CONFIG.friction_coulomb, CONFIG.friction_viscous, 0.0)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(speed=st.floats(0.0, 3.0), heading=st.floats(-math.pi, math.pi), yaw_rate=st.floats(-4.0, 4.0),
       normal=st.floats(-math.pi, math.pi), psi=st.floats(-0.5, 0.5))
def test_a_braked_stop_advances_a_row_no_further_than_the_energy_bound(speed, heading, yaw_rate, normal, psi):
    """On the plant: from any translation and any yaw rate, at any yaw, the largest advance along any
    direction n in the plane, and the largest turn either way, while the brakes stop the robot are at
    most the model's reach of those rows (s_t(S_t) and s_ψ(S_ψ) from the energy speeds) — the bound
    the governor and the speed-aware sets rely on."""
    v = np.array([speed * math.cos(heading), speed * math.sin(heading), yaw_rate])
    if not np.any(v):
        return
    path = _braked_path(v[:2], psi, yaw_rate)
    n = np.array([math.cos(normal), math.sin(normal), 0.0])
    rows = np.array([n, [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    measured = [float(np.max((path - path[0]) @ row)) for row in rows]
    bound = BRAKES.state_reach(rows, v)
    assert all(m <= b + 1e-6 for m, b in zip(measured, bound)), (measured, bound)


def test_a_turning_stop_needs_the_energy_of_both_blocks():
    """Not vacuous: at 0.5 m/s turning at 1 rad/s the robot brakes farther than its translation speed
    alone allows (the brakes also stop the turn), and from a straight 1 m/s with no yaw rate (at a yaw
    of 1.4 rad, off the wheels' symmetry) it turns more than 0.1 rad (the brakes spin it up): each
    block's path needs the other's speed."""
    turning = _braked_path(np.array([0.5, 0.0]), psi_dot=1.0)
    alone = BRAKES.blocks[0].distance(0.5)
    assert float(np.max(turning[:, 0])) > 1.1 * alone
    straight = _braked_path(np.array([0.0, 1.0]), psi=1.4)
    assert float(np.max(np.abs(straight[:, 2] - 1.4))) > 0.1


def test_a_braked_stop_turns_the_velocity_so_no_direction_can_be_left_out():
    """Heading 15° off a wheel's null direction, the stop drifts sideways: a row along the normal
    to v advances, which a straight-line stop would not allow (the bound takes every direction)."""
    v0 = 1.0 * np.array([math.cos(math.radians(15.0)), math.sin(math.radians(15.0))])
    path = _braked_path(v0)
    sideways = np.array([-v0[1], v0[0]])
    drift = max(float(np.max(path[:, :2] @ sideways)), float(np.max(path[:, :2] @ -sideways)))
    assert drift > 1e-3


def _held_torque_deviation(q0, v0, tau, hold, steps=400):
    """RK4 of the plant without friction or brakes under the wheel torques τ held `hold` s: the
    largest |q_xy(t) − q0 − v0t − ½a0t²| and |q̇_xy(t) − v0 − a0t| and the same for the yaw, a0 the
    model's acceleration at the start. The wheels must stay below the drives' speed limit (beyond it
    the plant's drives give no torque): asserted."""
    plant = Plant(MODEL, RobotSimConfig(friction_viscous=0.0, friction_coulomb=0.0))
    a0 = MODEL.acceleration(q0, v0, np.array(MODEL.wheel_map.generalised_force(q0.tolist(), tau)))
    state, h = plant.initial_state(q0, v0), hold / steps
    worst = np.zeros(4)
    for k in range(1, steps + 1):
        state = plant.step(state, tau, h)
        t = k * h
        dq, dv = state.q - (q0 + v0 * t + 0.5 * a0 * t * t), state.qd - (v0 + a0 * t)
        worst = np.maximum(worst, [np.hypot(*dq[:2]), np.hypot(*dv[:2]), abs(dq[2]), abs(dv[2])])
        assert max(abs(w) for w in plant.wheel_speeds(state)) < CONFIG.wheel_speed_limit
    return worst, a0


@settings(max_examples=60, deadline=None, derandomize=True)
@given(psi=st.floats(-math.pi, math.pi), speed=st.floats(0.0, 1.2), heading=st.floats(-math.pi, math.pi),
       yaw_rate=st.floats(-3.0, 3.0), tau=st.tuples(*[st.floats(-4.0, 4.0)] * 3), hold=st.sampled_from((0.02, 0.1)))
def test_held_wheel_torques_depart_from_constant_acceleration_no_more_than_the_hold_deviation(
        psi, speed, heading, yaw_rate, tau, hold):
    """The drives hold wheel torques: the world-frame force turns with the robot. On the plant (no
    friction, so the model's dynamics), the motion departs from q0 + v0t + ½a0t² by at most the hold
    deviation's (x_t, y_t), and the yaw not at all."""
    q0 = np.array([0.0, 0.0, psi])
    v0 = np.array([speed * math.cos(heading), speed * math.sin(heading), yaw_rate])
    worst, a0 = _held_torque_deviation(q0, v0, tau, hold)
    (x, x_yaw), (y, y_yaw) = BACKUP.hold_deviation.by_block([speed, abs(yaw_rate)],
                                                            [math.hypot(*a0[:2]), abs(a0[2])], hold)
    assert worst[0] <= x + 1e-9 and worst[1] <= y + 1e-9, (worst, x, y)
    assert worst[2] <= 1e-9 and worst[3] <= 1e-9 and x_yaw == 0.0 and y_yaw == 0.0


def test_a_turning_hold_departs_from_constant_acceleration():
    """Not vacuous: 100 ms of 4 N·m on one wheel while turning at 2 rad/s moves the robot millimetres
    off the constant-acceleration line, and the bound is within a factor 3 of it."""
    q0, v0 = np.zeros(3), np.array([1.0, 0.0, 2.0])
    worst, a0 = _held_torque_deviation(q0, v0, (4.0, 0.0, 0.0), 0.1)
    (x, _), (y, _) = BACKUP.hold_deviation.by_block([1.0, 2.0], [math.hypot(*a0[:2]), abs(a0[2])], 0.1)
    assert worst[0] > 2e-3
    assert worst[0] <= x < 3.0 * worst[0]


@settings(max_examples=60, deadline=None, derandomize=True)
@given(x=st.floats(-0.8, 0.8), y=st.floats(-0.8, 0.8), psi=st.floats(-1.0, 1.0), speed=st.floats(0.0, 2.0),
       heading=st.floats(-math.pi, math.pi), yaw_rate=st.floats(-2.0, 2.0))
def test_the_fallback_never_lowers_the_state_s_backup_margin(x, y, psi, speed, heading, yaw_rate):
    """Under u_g (held one period, the model integrated finely) the state's backup margin does not
    decrease: the step of the invariance argument in docs/control.md §10, for the planar rows and
    the yaw rows of the box, turning or not."""
    q = np.array([x, y, psi])
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
    if out.share > 0.0:                              # moved from u towards the fallback u_g, never past it
        u_g = MODEL.inverse_dynamics(q, v, BACKUP.fallback_acceleration(v))
        assert out.u[0] == pytest.approx(u[0] + out.share * (u_g[0] - u[0]), abs=1e-9)
        assert min(u[0], u_g[0]) <= out.u[0] <= max(u[0], u_g[0])


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
    _check_no_more_than_needed(x, y, speed, heading, push)


@pytest.mark.parametrize("x, speed, push", [(0.3125, 0.78125, 312.0), (0.5, 1.150390625, 113.0)])
def test_govern_finds_the_least_lambda_where_its_merit_turns_flat(x, speed, push):
    """Two examples the property above met (Hypothesis draws part of its examples from the literals of the
    project's modules loaded in the process, so whether its run meets them depends on what it imported).
    Along u → u_g the merit is far below 0 at u (−1.31, −0.22), just above it at u_g (+0.014, +0.0006) and
    flat from λ ≈ 0.37 (0.385): the chords start next to u_g and creep down, and after the 12 allowed the
    search sent 0.389 and 0.443 where 0.361 and 0.380 pass. The search now bisects what they leave."""
    _check_no_more_than_needed(x, 0.0, speed, 0.0, push)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(x=st.floats(-0.9, 0.9), y=st.floats(-0.9, 0.9), psi=st.floats(-1.3, 1.3), speed=st.floats(0.0, 1.5),
       heading=st.floats(-math.pi, math.pi), push=st.floats(50.0, 400.0), direction=st.floats(-math.pi, math.pi),
       twist=st.floats(-400.0, 400.0))
def test_govern_changes_a_twisting_command_no_more_than_needed(x, y, psi, speed, heading, push, direction, twist):
    """The same with a yaw torque in the command, anywhere in the box and from rest. The hold's deviation
    grows with the yaw acceleration; judged once for the whole segment at its largest block norms, it
    failed every blend of such a command — a holding machine's law asking for (−302, 370, 342), far from
    its reference, had the fallback sent at every sample, and the robot stood still (docs/control.md §10)."""
    u = np.array([push * math.cos(direction), push * math.sin(direction), twist])
    _check_no_more_than_needed(x, y, speed, heading, 0.0, u, psi)


TWISTING_WISH = {
    "name": "twisting-wish", "duration": 2.0, "dt": 0.001, "robot": {"kind": "omni3"},
    "region": [{"K": [[-1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1]],
                "T": [-1, 0.5, -4, -math.pi / 2, -math.pi / 2]}],
    "initial": {"q": [0.0, 2.0, 0.0], "qdot": [0.0, 0.0, 0.0]},
    "desired": {"kind": "point", "at": [-3.0, 6.0, 2.5]},      # beyond the corner x = −1, y = 4 and ψ = π/2
    "human": {"kind": "adversarial", "kp": 60.0},
}


@pytest.mark.parametrize("law", ["ce", "nce", "of"])
def test_a_machine_holding_a_twisting_push_moves_the_robot_towards_its_reference(law):
    """An operator pushing at full deflection towards a wish beyond a corner and past the ψ limit: the stop's
    yaw reach makes the state hazardous within 15 ms, in open space, and the machine holds authority while
    the push lasts. Its law then asks for some hundred newtons towards the projected reference; with the
    governor failing every blend of that command (the segment's bound above) the fallback was sent at every
    sample and the robot stood 2.6 m from its reference for the whole run. Now, in 2 s, it covers at least
    a sixth of the way, inside the set."""
    loop, q0, v0 = parse(TWISTING_WISH).closed_loop(law)
    trace = simulate(loop, q0, v0, 2.0, 0.001)
    assert trace.inside.all()
    assert trace.authority[-1] == Authority.MACHINE
    start_gap = np.linalg.norm(q0 - trace.q_r[-1])
    assert np.linalg.norm(trace.q[-1] - trace.q_r[-1]) <= (5.0 / 6.0) * start_gap


def _check_no_more_than_needed(x, y, speed, heading, push, u=None, psi=0.0):
    q = np.array([x, y, psi])
    v = np.array([speed * math.cos(heading), speed * math.sin(heading), 0.0])
    u = np.array([push, 0.0, 0.0]) if u is None else u
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


R = _LAMBDA_RESOLUTION


def _probed(merit):
    """merit, with the λ it was asked at kept in `.at`."""
    def counted(lam):
        counted.at.append(lam)
        return merit(lam)
    counted.at = []
    return counted


@settings(max_examples=300, deadline=None, derandomize=True)
@given(root=st.floats(R, 1.0), slope=st.floats(1e-3, 1e3), bend=st.floats(-0.9, 0.9), hint=st.floats(-0.5, 1.5))
def test_with_any_hint_the_search_ends_at_the_least_passing_grid_point_of_a_monotone_merit(root, slope, bend, hint):
    """docs/control.md §10, the warm start: on an increasing merit every search that closes its
    bracket ends at the least grid point that passes, cold or told any λ; a hint at that point
    settles it in two probes."""
    def merit(lam):       # increasing, its sign changes at `root`, bent so that a chord misses
        d = lam - root
        return slope * (d + bend * abs(d) * d)

    least = math.ceil(root / R) * R
    cold = _root(merit, merit(0.0), merit(1.0), BACKUP)
    warm = _probed(merit)
    assert cold == least and _root(warm, merit(0.0), merit(1.0), BACKUP, hint) == least
    assert all(round(lam / R) * R == lam for lam in warm.at)              # every probe on the grid
    assert len(warm.at) <= BACKUP.iterations + 12     # the chords, then bisection of what they leave (2¹² steps)
    told = _probed(merit)
    if least < 1.0:
        assert _root(told, merit(0.0), merit(1.0), BACKUP, least) == least
        assert len(told.at) == (1 if least == R else 2)        # at λ = 2⁻¹² the bracket [0, λ] is closed


@settings(max_examples=300, deadline=None, derandomize=True)
@given(values=st.lists(st.floats(-1.0, 1.0), min_size=2, max_size=40), hint=st.floats(0.0, 1.0))
def test_with_any_hint_the_search_sends_a_probe_that_passed_whatever_the_merit(values, hint):
    """On any merit (here a random one, constant on bins of λ) the warm search returns 1 or a probed
    λ that passed; where its bracket closed, the grid point below it failed."""
    def merit(lam):
        return values[min(int(lam * len(values)), len(values) - 1)]

    lo_value = min(values[0], -1e-3)
    merit_of = _probed(lambda lam: lo_value if lam == 0.0 else 1.0 if lam == 1.0 else merit(lam))
    hi = _root(merit_of, lo_value, 1.0, BACKUP, hint)
    verdict = {lam: merit(lam) for lam in merit_of.at}
    assert hi == 1.0 or (hi in verdict and verdict[hi] >= 0.0)
    if hi - R in verdict:
        assert verdict[hi - R] < 0.0


@settings(max_examples=60, deadline=None, derandomize=True)
@given(x=st.floats(0.2, 0.9), y=st.floats(-0.8, 0.8), speed=st.floats(0.5, 2.5), heading=st.floats(-0.8, 0.8),
       push=st.floats(50.0, 400.0), hint=st.floats(0.0, 1.0))
def test_govern_told_any_last_share_sends_a_backup_safe_command(x, y, speed, heading, push, hint):
    """The governor told any λ (the last period's, in the sampled loop) sends what the cold one may:
    the command when it passes, else a command that passes, within 0.005 of the least λ (the oracle
    of test_govern_changes_the_command_no_more_than_needed)."""
    q = np.array([x, y, 0.0])
    v = np.array([speed * math.cos(heading), speed * math.sin(heading), 0.0])
    u = np.array([push, 0.0, 0.0])
    cold, warm = govern(BACKUP, MODEL, BOX, q, v, u, 0.002), govern(BACKUP, MODEL, BOX, q, v, u, 0.002, hint=hint)
    assert warm.feasible == cold.feasible and (warm.share == 0.0) == (cold.share == 0.0)
    if warm.share == 0.0 or not warm.feasible:
        np.testing.assert_array_equal(warm.u, cold.u)
        return
    assert _passes(q, v, warm.u)
    u_g = MODEL.inverse_dynamics(q, v, BACKUP.fallback_acceleration(v))
    lo, hi = 0.0, 1.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if _passes(q, v, u + mid * (u_g - u)) else (mid, hi)
    assert warm.share - hi <= 0.005


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


@settings(max_examples=80, deadline=None, derandomize=True)
@given(speed=st.floats(0.0, 3.0), heading=st.floats(-math.pi, math.pi), yaw_rate=st.floats(-3.0, 3.0),
       accel=st.floats(0.0, 60.0), turn=st.floats(-math.pi, math.pi), yaw_accel=st.floats(-80.0, 80.0),
       observed=st.booleans())
def test_the_crude_row_bound_covers_the_command_s_and_the_next_state_s_reach(speed, heading, yaw_rate, accel, turn,
                                                                              yaw_accel, observed):
    """Σ_b |K_j,b| C_b (`_block_bounds`) is at least each row's exact command reach, and at least its
    advance over one period plus the next state's reach (with the period's own deviation, and under
    output feedback the slack): so the rows it sets aside cannot change the governor's decision."""
    from sharedctl.backup import _block_bounds, _crude_rows, _deviation, _rows_of, _spread, _state_reach
    dt, K = 0.002, np.array([[1.0, 0.0, 0.0], [-0.6, 0.8, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    rows = _rows_of(BACKUP, K)
    v = [speed * math.cos(heading), speed * math.sin(heading), yaw_rate]
    a = [accel * math.cos(turn), accel * math.sin(turn), yaw_accel]
    slack = list(BACKUP.observer_error) if observed else None
    crude = _crude_rows(_block_bounds(BACKUP, v, a, dt, slack))(rows)
    command = BACKUP.command_reach(K, v, a, slack)
    speeds = [math.hypot(v[0], v[1]), abs(v[2])]
    eps = slack or [0.0, 0.0]
    eta = _spread(BACKUP, speeds, slack)
    dq, dv = _deviation(BACKUP, [s + e for s, e in zip(speeds, eps)],
                        [math.hypot(a[0], a[1]) + eta[0], abs(a[2]) + eta[1]], dt)
    moved = [e * dt + 0.5 * h * dt * dt + x for e, h, x in zip(eps, eta, dq)]
    v1 = [vi + ai * dt for vi, ai in zip(v, a)]
    state = _state_reach(BACKUP, rows, v1, [e + h * dt + y for e, h, y in zip(eps, eta, dv)], None, observed)
    for j, (k, _, parts) in enumerate(rows):
        period = sum(ki * (vi * dt + 0.5 * ai * dt * dt) for ki, vi, ai in zip(k, v, a)) \
            + parts[0][1] * moved[0] + parts[1][1] * moved[1]
        assert command[j] <= crude[j] + 1e-12
        assert period + state[j] <= crude[j] + 1e-12


def _held_then_braked(q, v, u, hold=CONFIG.watchdog_timeout, dt=1e-3):
    """On the plant: the wheel torques of u at q held `hold` s, then the brakes to rest; the least
    margin of BOX's rows (|x|, |y| ≤ 1, |ψ| ≤ 1.5) on the way."""
    plant = Plant(MODEL, CONFIG)
    state = plant.initial_state(q, v)
    tau = MODEL.wheel_map.wheel_torques(q.tolist(), u.tolist())
    brakes = plant.brake_torques((True, True, True))
    smallest = BOX.margin(state.q)
    for k in range(40_000):
        held = k * dt < hold
        state = plant.step(state, tau if held else (0.0, 0.0, 0.0), dt, (0.0, 0.0, 0.0) if held else brakes)
        smallest = min(smallest, BOX.margin(state.q))
        if not held and np.linalg.norm(state.qd) < 1e-4:
            break
    return smallest


def _corners(v_hat, slack):
    """Velocities at the slack's edge around v̂: ±ε_t along and across the translation, ±ε_ψ on the yaw."""
    e_t, e_psi = slack
    return [v_hat + np.array([dx * e_t, dy * e_t, dpsi * e_psi])
            for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)) for dpsi in (1, -1)]


@settings(max_examples=20, deadline=None, derandomize=True)
@given(x=st.floats(0.3, 0.8), speed=st.floats(0.5, 1.8), heading=st.floats(-0.6, 0.6), yaw_rate=st.floats(-1.0, 1.0),
       push=st.floats(100.0, 400.0))
def test_govern_with_the_observer_s_error_sends_a_command_whose_stop_ends_inside_from_every_velocity_within_it(
        x, speed, heading, yaw_rate, push):
    """Output feedback: the governor given v̂ and the slack ε sends a command that, held T_w on the
    plant from any velocity at the slack's edge and braked, stays inside the box."""
    q = np.array([x, 0.0, 0.0])
    v_hat = np.array([speed * math.cos(heading), speed * math.sin(heading), yaw_rate])
    slack = BACKUP.observer_error
    out = govern(BACKUP, MODEL, BOX, q, v_hat, np.array([push, 0.0, 0.0]), 0.002, slack)
    if not out.feasible:
        return
    assert all(_held_then_braked(q, v, out.u) > 0.0 for v in _corners(v_hat, slack))


def test_without_the_slack_the_observer_s_error_carries_the_stop_outside():
    """Not vacuous: turning at v̂ = 1 rad/s at ψ = 1.1 towards the yaw face 1.5, the truth 1.5 rad/s (within
    ε_ψ), a 20 N·m push on the yaw: the command governed on v̂ alone turns the robot past the face from
    the truth, the one governed with the slack stops inside."""
    q, v_hat = np.array([0.0, 0.0, 1.1]), np.array([0.0, 0.0, 1.0])
    v = v_hat + np.array([0.0, 0.0, BACKUP.observer_error[1]])
    u = np.array([0.0, 0.0, 20.0])
    trusting = govern(BACKUP, MODEL, BOX, q, v_hat, u, 0.002)
    doubting = govern(BACKUP, MODEL, BOX, q, v_hat, u, 0.002, BACKUP.observer_error)
    assert trusting.feasible and doubting.feasible and doubting.share > trusting.share
    assert _held_then_braked(q, v, trusting.u) < 0.0 < _held_then_braked(q, v, doubting.u)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(psi=st.floats(-math.pi, math.pi), speed=st.floats(0.0, 1.2), heading=st.floats(-math.pi, math.pi),
       yaw_rate=st.floats(-2.0, 2.0), corner=st.integers(0, 7), lag=st.integers(1, 25),
       force=st.tuples(st.floats(-150.0, 150.0), st.floats(-150.0, 150.0), st.floats(-10.0, 10.0)))
def test_the_uncertain_prediction_holds_every_state_the_slack_leaves_possible(psi, speed, heading, yaw_rate, corner,
                                                                              lag, force):
    """From (q, v̂) with the slack ε, over `lag` periods of one command (converted to wheel torques at each
    period's start and held, as the drives hold it; the plant without friction, so the model's dynamics):
    the plant started at a velocity on the slack's edge ends within the predicted slack and offset of
    the predicted state, block by block."""
    from sharedctl.backup import uncertain_prediction
    q0 = np.array([0.0, 0.0, psi])
    v_hat = np.array([speed * math.cos(heading), speed * math.sin(heading), yaw_rate])
    u = np.array(force)
    dt = 0.002
    q_p, v_p, slack, offset = uncertain_prediction(BACKUP, MODEL, q0, v_hat, BACKUP.observer_error, [u] * lag, dt)
    plant = Plant(MODEL, RobotSimConfig(friction_viscous=0.0, friction_coulomb=0.0))
    state = plant.initial_state(q0, _corners(v_hat, BACKUP.observer_error)[corner])
    for _ in range(lag):
        tau = MODEL.wheel_map.wheel_torques(state.q.tolist(), u.tolist())
        for _ in range(4):
            state = plant.step(state, tau, dt / 4)
    dq, dv = state.q - q_p, state.qd - v_p
    assert np.hypot(*dq[:2]) <= offset[0] + 1e-9 and abs(dq[2]) <= offset[1] + 1e-9, (dq, offset)
    assert np.hypot(*dv[:2]) <= slack[0] + 1e-9 and abs(dv[2]) <= slack[1] + 1e-9, (dv, slack)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(psi=st.floats(-math.pi, math.pi), speed=st.floats(0.0, 1.2), heading=st.floats(-math.pi, math.pi),
       yaw_rate=st.floats(-2.0, 2.0), corner=st.integers(0, 7),
       spans=st.lists(st.floats(0.0005, 0.012), min_size=1, max_size=12),
       forces=st.lists(st.tuples(st.floats(-150.0, 150.0), st.floats(-150.0, 150.0), st.floats(-10.0, 10.0)),
                       min_size=12, max_size=12))
def test_the_uncertain_prediction_over_commands_held_unequal_times_holds_every_state_the_slack_leaves_possible(
        psi, speed, heading, yaw_rate, corner, spans, forces):
    """As above, with each command held its own time (shared_controller.in_flight's spans: ticks that came
    late): the plant, driven by each command for its time, ends within the predicted slack and offset."""
    from sharedctl.backup import uncertain_prediction
    q0 = np.array([0.0, 0.0, psi])
    v_hat = np.array([speed * math.cos(heading), speed * math.sin(heading), yaw_rate])
    commands = [np.array(f) for f in forces[:len(spans)]]
    q_p, v_p, slack, offset = uncertain_prediction(BACKUP, MODEL, q0, v_hat, BACKUP.observer_error, commands, spans)
    plant = Plant(MODEL, RobotSimConfig(friction_viscous=0.0, friction_coulomb=0.0))
    state = plant.initial_state(q0, _corners(v_hat, BACKUP.observer_error)[corner])
    for u, h in zip(commands, spans):
        tau = MODEL.wheel_map.wheel_torques(state.q.tolist(), u.tolist())
        for _ in range(8):
            state = plant.step(state, tau, h / 8)
    dq, dv = state.q - q_p, state.qd - v_p
    assert np.hypot(*dq[:2]) <= offset[0] + 1e-9 and abs(dq[2]) <= offset[1] + 1e-9, (dq, offset)
    assert np.hypot(*dv[:2]) <= slack[0] + 1e-9 and abs(dv[2]) <= slack[1] + 1e-9, (dv, slack)


def _plain_uncertain_prediction(backup, model, q, v, slack, commands, dt):
    """uncertain_prediction as its docstring states it, one helper call per term: per period the bound
    (ε + 2(g(g(ε)) − ε), doubled away from ε until g maps it below itself), then ε, η and x from it."""
    from sharedctl.backup import _block_speeds, _deviation, _norm, _spread

    def grown(speeds, accelerations, eps, bound):
        fastest = [s + al * dt for s, al in zip(speeds, accelerations)]
        eta = _spread(backup, fastest, bound)
        dq, dv = _deviation(backup, [s + e for s, e in zip(speeds, eps)],
                            [al + h for al, h in zip(accelerations, eta)], dt)
        return [e + h * dt + y for e, h, y in zip(eps, eta, dv)], eta, dq

    eps, offset = [float(e) for e in slack], [0.0] * len(backup.blocks)
    for u in commands:
        a = model.acceleration(q, v, u)
        speeds = _block_speeds(backup, v.tolist())
        accelerations = [_norm([a.tolist()[i] for i in block.axes]) for block in backup.blocks]
        bound = [e + 2.0 * (g - e) for e, g in zip(eps, grown(speeds, accelerations, eps,
                                                                 grown(speeds, accelerations, eps, eps)[0])[0])]
        while any(g > b for g, b in zip(grown(speeds, accelerations, eps, bound)[0], bound)):
            bound = [e + 2.0 * (b - e) + 1e-12 for e, b in zip(eps, bound)]
        end, eta, dq = grown(speeds, accelerations, eps, bound)
        offset = [p + e * dt + 0.5 * h * dt * dt + x for p, e, h, x in zip(offset, eps, eta, dq)]
        eps = end
        q, v = q + dt * v + 0.5 * dt * dt * a, v + dt * a
    return q, v, eps, offset


@settings(max_examples=60, deadline=None, derandomize=True)
@given(q=st.tuples(*[st.floats(-3.0, 3.0)] * 3), v=st.tuples(*[st.floats(-2.5, 2.5)] * 3),
       slack=st.tuples(st.floats(0.0, 0.3), st.floats(0.0, 1.0)), lag=st.integers(0, 30), seed=st.integers(0, 2**31))
def test_the_uncertain_prediction_is_its_stated_recursion_to_the_bit(q, v, slack, lag, seed):
    """backup.uncertain_prediction (which looks the hold deviation's methods up once per call and keeps the
    last check of the bound as the period's growth) gives the floats of the recursion written plainly."""
    from sharedctl.backup import uncertain_prediction
    rng = np.random.default_rng(seed)
    commands = [rng.uniform(-150.0, 150.0, 3) for _ in range(lag)]
    q, v = np.array(q), np.array(v)
    fast = uncertain_prediction(BACKUP, MODEL, q, v, slack, commands, 0.002)
    plain = _plain_uncertain_prediction(BACKUP, MODEL, q, v, slack, commands, 0.002)
    assert np.array_equal(fast[0], plain[0]) and np.array_equal(fast[1], plain[1])
    assert list(fast[2]) == list(plain[2]) and list(fast[3]) == list(plain[3])


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


def test_the_simulator_searches_the_governor_s_share_once_a_step_and_holds_it_over_the_stages(monkeypatch):
    """simulator.simulate treats λ as part of the step's decision (docs/control.md §10): one search per
    step, from the step's start, and the sample records the command that search sent (searched at every
    RK stage, the rate switched inside a step wherever the state sat at the envelope's edge, and the
    step-size control halved such steps to their floor: 1,700 rate evaluations a step for one robot of
    the bench's fleet)."""
    import sharedctl.simulator as sim
    from sharedctl.human import AdversarialOperator, LineTrajectory
    from sharedctl.simulator import ClosedLoop, simulate

    scenario = load("adversarial_wall")
    base = scenario.closed_loop("ce")[0]
    target = np.array([0.3, 5.0, 0.0])
    loop = ClosedLoop(base.model, base.feasible, AdversarialOperator(LineTrajectory(target, np.zeros(3)),
                                                                     np.full(3, 30.0), target, 1.0),
                      base.controller, base.sharing, base.reference, base.theta_hat0, base.backup)
    calls, sent = [], []
    real = sim.govern

    def counted(*args, **kw):
        out = real(*args, **kw)
        calls.append(args[4].copy())
        sent.append(out.u)
        return out

    monkeypatch.setattr(sim, "govern", counted)
    trace = simulate(loop, np.array([0.0, 3.9, 0.0]), np.array([0.0, 0.8, 0.0]), 0.2, 0.001)
    machine = np.flatnonzero(trace.authority != 0)
    assert machine.size > 0, "the machine never acted: the case would test nothing"
    assert len(calls) == machine.size <= trace.t.size
    np.testing.assert_allclose(np.array(sent), trace.u_s[machine], rtol=0, atol=1e-12)
    assert any(not np.allclose(s, c) for s, c in zip(sent, calls)), "the governor never acted"
