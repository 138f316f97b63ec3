"""Invariance of the admissible set under the shared controller (omnidirectional robot).

The safety property: from any initial state inside Q_a, whatever the operator commands,
every sample of the closed loop stays inside Q_a (trace.inside all True), every signal stays
finite and the run completes — for the three machine controllers ce (12), nce ((12) with the composite update on the
filters (14)–(15), in both roles), and of (25)+(40).

Runs use dt = 2e-3 (the plant is integrated by RK4 at the control period).

What the generated sets satisfy, and why
----------------------------------------
The sharing arbiter hands the machine ONE constraint group (n = 3 rows with invertible K_i)
and the machine law only keeps that group's rows negative. So every row that can be
hazardous at one instant must fit in one invertible group:

* bands b1 = 0.3 m, b2 = 0.6 m (the defaults);
* polygon faces are 1.0–3.0 m from a centre, with consecutive outward normals 40°–150°
  apart: the normals positively span the plane, so each polygon is bounded, and no two faces
  are parallel and close (a corridor is ≥ 2 m wide, wider than 2·b2 = 1.2 m: opposite faces
  are never both inside the bands);
* no point of a polygon is within b2 of three of its faces (checked by linear programming in
  strategies.check_band_assumptions): at most two planar rows (a corner) plus one ψ row can
  be hazardous together, and those three rows form an invertible group;
* ψ rows are ψ ≤ π/2 and −ψ ≤ π/2 (parallel: never in one group, never both near);
* the non-convex sets are the union of two rectangles (each ≥ 2 m wide) forming an L or a T.

Initial states: q0 with slack ≥ 0.4 m, |v0| ≤ 0.3 m/s (random sets); or 0.5 m from a face
moving towards it at 1–3 m/s (fast approach). The operator (a damped spring, k_p = 20,
k_d = 12, the paper scenarios' imitation) follows a desired line or circle that leaves the
set within 4–5 s; adversarial operators push with 50–200 N (constant, bang-bang or random
forces re-drawn every 0.2 s, ≤ 10 N·m about ψ).

Every random case is built from one integer seed; a failure message names the builder and
the seed, e.g. `random_convex_case(17)`, which rebuilds the case exactly.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings

sys.path.insert(0, str(Path(__file__).resolve().parent))
import strategies as S

from sharedctl.sets import SetClass, classify
from sharedctl.sharing import Mode, SharingParameters

SIM = S.SIM_SETTINGS


def assert_invariant(case, controller):
    trace = S.run(case, controller)
    failure = S.invariance_failure(case, controller, trace)
    assert failure is None, failure
    return trace


# ----- the paper's scenarios ---------------------------------------------------------------
@pytest.mark.parametrize("controller", S.CONTROLLERS)
@pytest.mark.parametrize("name", ["paper_convex", "paper_nonconvex"])
def test_paper_scenario_stays_inside(name, controller):
    """Shortened paper scenarios (strategies.PAPER_SHIFT: the file's line entered later, 5 s)."""
    trace = assert_invariant(S.paper_case(name), controller)
    # not vacuous: the machine had to act, and came close to a face
    assert np.any(trace.set_class == 2), "the run never reached the hazardous set"
    assert trace.margin.min() < 0.1


def test_paper_nonconvex_variant_rounds_the_obstacle_corner():
    """The shortened non-convex run really crosses from {x ≤ 0} into {y ≤ 0} past (0, 0)."""
    trace = S.run(S.paper_case("paper_nonconvex"), "ce")
    assert np.any((trace.q[:, 0] > 0.05) & (trace.q[:, 1] < 0.0))
    assert np.any((trace.q[:, 0] < 0.0) & (trace.q[:, 1] > 1.0))


# ----- random convex polygons ----------------------------------------------------------------
def test_generated_convex_cases_meet_the_stated_assumptions():
    """The generator itself: q0 slack ≥ 0.4 m, |v0| ≤ 0.3 m/s, bounded polygon with the
    three-face clearance, and a desired trajectory that leaves the set (no simulation)."""
    for seed in range(12):
        case = S.random_convex_case(seed)
        K, T = case.regions[0]
        assert np.all(S.slacks(K, T, case.q0) >= 0.4 - 1e-12)
        assert np.linalg.norm(case.v0) <= 0.3 + 1e-12
        assert S.planar_triple_clearance(K, T, 2) > S.BANDS.b2
        assert 3 <= len(K) - 2 <= 5
        assert S.first_exit_time(case.regions, case.human.trajectory, case.duration) is not None
        assert S.is_bounded(K)


@pytest.mark.parametrize("controller", S.CONTROLLERS)
@settings(max_examples=3, **SIM)
@given(case=S.convex_cases)
def test_random_convex_set_stays_inside(controller, case):
    trace = assert_invariant(case, controller)
    assert np.any(trace.set_class == 2), "the run never reached the hazardous set"


# ----- random non-convex unions -----------------------------------------------------------------
def test_generated_union_cases_leave_through_the_notch():
    """The union generator: q0 in the first rectangle with slack ≥ 0.4 m, both rectangles
    overlap, and the desired line leaves the union (no simulation)."""
    for seed in range(10):
        case = S.random_union_case(seed)
        (KA, TA), (KB, TB) = case.regions
        assert np.all(S.slacks(KA, TA, case.q0) >= 0.4 - 1e-12)
        assert S.first_exit_time(case.regions, case.human.trajectory, case.duration) is not None
        # the rectangles overlap in a disc of radius ≥ 1 m (each is ≥ 2 m wide)
        assert S.common_slack(case.regions) >= 1.0 - 1e-9, case.label
        assert S.planar_triple_clearance(KA, TA, 2) > S.BANDS.b2
        assert S.planar_triple_clearance(KB, TB, 2) > S.BANDS.b2


@pytest.mark.parametrize("controller", S.CONTROLLERS)
@settings(max_examples=2, **SIM)
@given(case=S.union_cases)
def test_random_nonconvex_union_stays_inside(controller, case):
    trace = assert_invariant(case, controller)
    assert np.any(trace.set_class == 2), "the run never reached the hazardous set"


# ----- adversarial operators and fast approaches ------------------------------------------------
@pytest.mark.parametrize("controller", S.CONTROLLERS)
@settings(max_examples=2, **SIM)
@given(case=S.adversarial_cases)
def test_adversarial_operator_cannot_push_the_robot_out(controller, case):
    trace = assert_invariant(case, controller)
    assert np.any(trace.set_class == 2), "the run never reached the hazardous set"


@pytest.mark.parametrize("controller", S.CONTROLLERS)
@settings(max_examples=2, **SIM)
@given(case=S.fast_approach_cases)
def test_fast_approach_towards_a_face_is_stopped(controller, case):
    trace = assert_invariant(case, controller)
    assert np.any(trace.set_class == 2), "the approach never became hazardous"


@pytest.mark.parametrize("speed", [1.0, 3.0])
def test_fast_approach_into_a_corner_is_stopped(speed):
    """0.5 m from both faces of the corner x = 0, y = 0, moving diagonally into it, ce law."""
    K = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]] + S.PSI_K
    T = [0.0, -3.0, 0.0, -3.0] + S.PSI_T
    q0 = np.array([-0.5, -0.5, 0.0])
    v0 = speed * np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    traj = S.LineTrajectory(q0.copy(), 0.3 * np.array([1.0, 1.0, 0.0]) / np.sqrt(2))
    case = S.Case(f"corner approach at {speed} m/s", "omni3", [(K, T)], q0, v0, S.scripted(traj, 3), 2.0)
    assert_invariant(case, "ce")


#: of at 8 m/s is not in the list: its observer starts from rest (v̂(0) = 0), so for the first periods
#: the law brakes for a robot 4–8 m/s slower than the true one — an observer error beyond the
#: configuration's stated bound (ṽ_max = 3 m/s, docs/control.md §4.3) — and the stop would need
#: some 50 kN within 8 mm, twenty times the drives' limit: outside every envelope this project states.
HAZARD_STARTS = [(sp, c) for sp in (3.0, 8.0) for c in S.CONTROLLERS if (sp, c) != (8.0, "of")]


@pytest.mark.parametrize("speed,controller", HAZARD_STARTS)
def test_start_inside_the_hazard_band_at_speed_is_stopped(speed, controller):
    """0.1 m from the face x = 0, moving into it at 3 or 8 m/s at t = 0 (hazardous from the
    first sample — for of only in truth: its observer starts from rest, v̂(0) = 0, so its
    arbiter first sees a safe state), the operator's line continuing through the face at
    0.3 m/s, for 1.5 s. At 8 m/s with ce and nce this once failed: the first stop drove θ̂₁
    to 58.8 (true 18.06), and when the operator leaned the robot back to 6 mm the re-engaged
    law's gains outran the 2 ms step; the parameter projection and the inner hazard band b0
    (docs/control.md §5, §6) removed both causes."""
    q0 = np.array([-0.1, 0.0, 0.0])
    direction = np.array([1.0, 0.0, 0.0])
    traj = S.LineTrajectory(q0.copy(), 0.3 * direction)
    case = S.Case(f"hazard start at {speed} m/s", "omni3", [S.rectangle(-3.0, 0.0, -3.0, 3.0)], q0,
                  speed * direction, S.scripted(traj, 3), 1.5)
    assert classify(case.feasible(), q0, case.v0, S.BANDS).overall is SetClass.HAZARD   # truly hazardous
    assert_invariant(case, controller)


CREEPS = [(0.05, 0.1), (0.05, 0.03), (0.005, 0.003)]   # (distance m, speed m/s)


@pytest.mark.parametrize("distance,speed", CREEPS)
def test_slow_approach_is_first_caught_at_a_distance_proportional_to_its_speed(distance, speed):
    """Definition 2 alone hands the machine authority at the first sample with ẋ ≥ f_b1(x): a
    creeping approach at speed s would be caught only |x| = s·b1²/(1 + s·b1) from the face
    (8.7 mm at 0.1 m/s, 2.7 mm at 0.03 m/s, 0.27 mm at 3 mm/s), where every law's forces are
    enormous (at 3 mm/s the CE law answered 2·10⁴ N and threw the robot out). The inner band
    b0 = 25 mm makes any approach closer than b0 hazardous, so the machine takes over at
    max(s·b1²/(1 + s·b1), b0). Seen through the fail-safe stop (docs/control.md §10), every row is
    moved towards its face by the stop's reach at the approach speed, s·T_w plus the braking path
    from s (straight at the face, the whole path counts): the take-over comes that much earlier."""
    case = S.creep_case(distance, speed)
    trace = S.run(case, "ce")
    first = S.takeover_samples(trace)[0]
    reach = S.stop_reach_bound(case.loop("ce").backup, case.v0)
    expected = min(distance, S.first_takeover_distance(speed) + reach)   # (0.005, 0.003) starts inside b0
    assert reach > 0.0
    assert trace.margin[first] == pytest.approx(expected, rel=0.05, abs=speed * S.DT)


@pytest.mark.parametrize("distance,speed,controller", [(d, s, c) for d, s in CREEPS for c in S.CONTROLLERS])
def test_slow_creep_into_a_face_is_stopped(distance, speed, controller):
    """The operator drifts into a face at 0.1, 0.03 or 0.003 m/s (scripted spring, desired
    line through the face): the machine takes over (at the inner band) and must hold it."""
    trace = assert_invariant(S.creep_case(distance, speed), controller)
    assert np.any(trace.set_class == 2)


# ----- the safety tests are not vacuous --------------------------------------------------------
@pytest.mark.parametrize("builder", [S.random_convex_case, S.random_union_case, S.adversarial_case])
def test_without_the_machine_the_generated_operators_leave_the_set(builder):
    """Mode.HUMAN (operator alone) on the first generated case of each family violates Q_a:
    the invariance above is the machine's doing."""
    case = builder(0)
    trace = S.run(case, "ce", sharing=SharingParameters(mode=Mode.HUMAN))
    assert not trace.inside.all()
