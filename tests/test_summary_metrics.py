"""The summary figures that show what each configuration does (metrics.summarize):

* transparency — among the samples whose true state (q, q̇) is in O_s, the share with u_s = u_h;
* law_share — among the samples with machine authority, the share whose u_f came from the
  configuration's own law (as the trace records which law ran);
* theta_error — |θ̂ − θ| / |θ| at the end of the run.

Oracles: shares counted by hand on hand-built traces; Definition 2 evaluated by hand on the
single face y ≤ 4 (f_b(x) = 1/(x + b) − 1/b, b0 = 0.025, b1 = 0.3, b2 = 0.6); θ of the omni
robot from its physical parameters by hand.
"""
from __future__ import annotations

import tomllib
from importlib import resources

import numpy as np
import pytest

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.human import LineTrajectory, ScriptedOperator
from sharedctl.metrics import machine_authority_time, peak_norm, rms_norm, share_above, summarize
from sharedctl.models import OmniRobot
from sharedctl.models.omni_robot import OmniRobotParameters
from sharedctl.scenario import parse
from sharedctl.sets import SetClass
from sharedctl.sharing import Authority, LawRole, Mode, SharingParameters
from sharedctl.simulator import ClosedLoop, Trace, make_controller, simulate

from .helpers import packaged_run

HUMAN, SHARED, MACHINE = int(Authority.HUMAN), int(Authority.SHARED), int(Authority.MACHINE)
SAFE, HYSTERESIS, HAZARD = int(SetClass.SAFE), int(SetClass.HYSTERESIS), int(SetClass.HAZARD)
DT = 0.001

#: states (y, ẏ) at the face y ≤ 4 (x = y − 4, ẋ = ẏ) and their Definition-2 class, by hand
HAND_STATES = [
    # x = −1.0 < −b2: no allowance applies                                            → safe
    ((3.0, 1.0), SAFE),
    # x = −0.5: f_b2 = 1/0.1 − 1/0.6 = 8.333 ≥ ẋ = 1; x < −b1                          → safe
    ((3.5, 1.0), SAFE),
    # x = −0.2: ẋ = −0.5 < 0 ≤ f_b2(−0.2) = 1/0.4 − 1/0.6 = 0.833                      → safe
    ((3.8, -0.5), SAFE),
    # x = −0.5: ẋ = 10 > f_b2 = 8.333, and x < −b1 (no hazard row)                      → hysteresis
    ((3.5, 10.0), HYSTERESIS),
    # x = −0.2: ẋ = 2 > f_b2 = 0.833, ẋ < f_b1(−0.2) = 1/0.1 − 1/0.3 = 6.667, x < −b0   → hysteresis
    ((3.8, 2.0), HYSTERESIS),
    # x = −0.2: ẋ = 7 ≥ f_b1 = 6.667                                                   → hazardous
    ((3.8, 7.0), HAZARD),
]


def hand_trace(authority, u_h, u_s, true_class=None, own_law=None, theta_hat=None, theta=None, q=None, v=None):
    """A Trace of a few samples, the columns a test does not set filled with NaN / −1."""
    u_h, u_s = np.asarray(u_h, float), np.asarray(u_s, float)
    steps, n = u_h.shape
    nan_n, nan_1 = np.full((steps, n), np.nan), np.full(steps, np.nan)
    labels = np.full(steps, -1)
    return Trace(
        t=np.arange(steps) * DT, q=nan_n if q is None else np.asarray(q, float),
        v=nan_n if v is None else np.asarray(v, float), v_hat=nan_n, q_d=nan_n, q_r=nan_n, u_h=u_h,
        u_f=nan_n, u_s=u_s, tau=u_s, theta_hat=np.zeros((steps, 3)) if theta_hat is None else np.asarray(theta_hat),
        authority=np.asarray(authority), set_class=labels, group=labels, role=labels, k_h=nan_1, k_f=nan_1,
        intent=nan_1, margin=np.ones(steps), inside=np.ones(steps, bool), finite=True, switches=0, group_switches=0,
        true_class=None if true_class is None else np.asarray(true_class),
        own_law=None if own_law is None else np.asarray(own_law, bool), theta=theta,
    )


def single_face_loop(controller, mode=Mode.SHARED, model=None, wish=(0.0, 2.0, 0.0), wish_velocity=(0.0, 0.0, 0.0)):
    """The omni robot below the single face y ≤ 4 (completed with far rows), a scripted operator."""
    model = model or OmniRobot()
    feasible = FeasibleSet.from_regions([Polytope.from_rows([[0.0, 1.0, 0.0]], [-4.0])])
    human = ScriptedOperator(LineTrajectory(np.array(wish, float), np.array(wish_velocity, float)),
                             np.full(3, 20.0), np.full(3, 12.0))
    return ClosedLoop(model, feasible, human, make_controller(controller, model=model), SharingParameters(mode=mode))


def packaged(name):
    return parse(tomllib.loads(resources.files("sharedctl").joinpath(f"scenarios/{name}.toml").read_text()))


# ----- transparency -----------------------------------------------------------------------------
def test_transparency_is_the_share_of_safe_samples_with_u_s_equal_to_u_h():
    samples = [  # (hand state, u_h, u_s, authority)
        (0, [5.0, -2.0, 0.1], [5.0, -2.0, 0.1], HUMAN),            # safe, equal                      → counts
        (1, [10.0, 0.0, 0.0], [8.0, 0.0, 0.0], SHARED),            # safe, blended                    → does not
        (2, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], HUMAN),              # safe, both zero                  → counts
        (0, [100.0, 0.0, 0.0], [100.0 + 1e-8, 0.0, 0.0], HUMAN),   # safe, |Δ| = 1e-8 ≤ 1e-9 · 100    → counts
        (1, [1.0, 0.0, 0.0], [1.0 + 1e-6, 0.0, 0.0], SHARED),      # safe, |Δ| = 1e-6 > 1e-9 · 1      → does not
        (3, [3.0, 0.0, 0.0], [3.0, 0.0, 0.0], HUMAN),              # hysteresis: not a safe sample
        (4, [4.0, 0.0, 0.0], [0.0, 4.0, 0.0], SHARED),             # hysteresis
        (5, [2.0, 2.0, 0.0], [-7.0, 0.0, 0.0], MACHINE),           # hazardous
    ]
    states = [HAND_STATES[i][0] for i, *_ in samples]
    trace = hand_trace([a for *_, a in samples], [u_h for _, u_h, _, _ in samples],
                       [u_s for _, _, u_s, _ in samples], true_class=[HAND_STATES[i][1] for i, *_ in samples],
                       q=[[0.0, y, 0.0] for y, _ in states], v=[[0.0, y_dot, 0.0] for _, y_dot in states])
    assert summarize(trace, DT)["transparency"] == pytest.approx(3 / 5, abs=1e-15)


def test_transparency_is_none_without_a_safe_sample():
    trace = hand_trace([MACHINE, SHARED], [[1.0, 0, 0]] * 2, [[1.0, 0, 0]] * 2, true_class=[HAZARD, HYSTERESIS])
    assert summarize(trace, DT)["transparency"] is None


@pytest.mark.parametrize("controller", ["ce", "of"])
@pytest.mark.parametrize("state,expected", HAND_STATES)
def test_the_recorded_true_class_is_definition_2_of_q_and_q_dot(controller, state, expected):
    """At t = 0 the observer's v̂ is 0 (the true q̇(0) is not measured), so under output feedback the
    arbiter sees every one of these states at rest: the true class must still follow q̇."""
    y, y_dot = state
    trace = simulate(single_face_loop(controller), [0.0, y, 0.0], [0.0, y_dot, 0.0], DT, DT)
    assert trace.true_class[0] == expected
    if controller == "of":
        assert trace.set_class[0] == SAFE          # (q, v̂ = 0): x < −b0 and ẋ = 0 — no row unsafe


def test_transparency_is_one_when_the_wish_stays_inside():
    """A wish moving slowly well inside the set (0.5 m and more from every face): the operator alone acts."""
    loop = single_face_loop("ce", wish=(0.0, 2.0, 0.0), wish_velocity=(0.05, 0.1, 0.02))
    trace = simulate(loop, [0.0, 2.0, 0.0], [0.0, 0.0, 0.0], 10.0, 0.002)
    assert np.max(trace.q[:, 1]) < 3.5 and np.max(np.linalg.norm(trace.u_h, axis=1)) > 0.1
    summary = summarize(trace, 0.002)
    assert np.all(trace.true_class == SAFE)
    assert summary["transparency"] == 1.0


# ----- law_share ----------------------------------------------------------------------------------
def test_law_share_is_the_share_of_machine_samples_run_by_the_own_law():
    authority = [HUMAN, MACHINE, MACHINE, SHARED, SHARED, HUMAN, MACHINE]
    own_law = [True, True, False, True, False, False, False]
    # machine samples: 1, 2, 3, 4, 6 (5 of them); own law among them: 1, 3  → 2/5
    trace = hand_trace(authority, [[0.0] * 3] * 7, [[0.0] * 3] * 7, own_law=own_law)
    assert summarize(trace, DT)["law_share"] == pytest.approx(2 / 5, abs=1e-15)


def test_law_share_is_none_when_the_machine_never_acts():
    trace = hand_trace([HUMAN] * 3, [[0.0] * 3] * 3, [[0.0] * 3] * 3, own_law=[False, True, False])
    assert summarize(trace, DT)["law_share"] is None


#: a start near a face, moving towards it (a take-over within a second)
NEAR_FACE = {"paper_convex": ([-0.5, 3.8, 0.0], [0.0, 1.5, 0.0]),
             "paper_nonconvex": ([-0.25, 1.0, 0.0], [1.5, 0.0, 0.0]),
             "adversarial_wall": ([0.0, 3.8, 0.0], [0.0, 0.5, 0.0])}


@pytest.mark.parametrize("name", sorted(NEAR_FACE))
def test_the_certainty_equivalent_configuration_always_runs_its_own_law(name):
    loop, _, _ = packaged(name).closed_loop("ce")
    q0, v0 = NEAR_FACE[name]
    trace = simulate(loop, q0, v0, 1.0, DT)
    assert np.count_nonzero(trace.authority != HUMAN) > 0, "the machine never acted: the case would test nothing"
    assert summarize(trace, DT)["law_share"] == 1.0


def test_a_fallback_to_another_configurations_law_does_not_count_as_the_own_law():
    """`of` with (12) put in its hazard role (a fallback: (12) is the `ce` configuration's law): on the
    adversarial wall the machine acts only in the hazard role, so only the tracking-role samples count.
    The oracle is the law role of each machine sample."""
    from sharedctl.controllers import CertaintyEquivalentLaw
    from sharedctl.simulator import MachineController

    scenario = packaged("adversarial_wall")
    loop, q0, v0 = scenario.closed_loop("of")
    machine_controller = loop.controller
    loop.controller = MachineController(machine_controller.tracking, CertaintyEquivalentLaw(),
                                        machine_controller.observer)
    trace = simulate(loop, q0, v0, scenario.duration, scenario.dt)
    machine = trace.authority != HUMAN
    tracking_role_share = float(np.mean(trace.role[machine] == int(LawRole.TRACKING)))
    law_share = summarize(trace, scenario.dt)["law_share"]
    assert law_share < 0.9
    assert law_share == pytest.approx(tracking_role_share, abs=1e-12)


def test_output_feedback_counts_its_barrier_law_in_the_hazard_role_as_its_own():
    """`of` runs its own barrier law on v̂ in the hazard role (docs/control.md §4.3): on the adversarial
    wall, where the machine acts in that role, every machine sample counts."""
    trace, dt = packaged_run("adversarial_wall", "of")
    machine = trace.authority != HUMAN
    assert np.any(trace.role[machine] == int(LawRole.HAZARD))
    assert summarize(trace, dt)["law_share"] == 1.0


# ----- theta_error --------------------------------------------------------------------------------
def test_theta_error_is_the_relative_distance_to_the_robots_theta():
    """θ = [m1, m3, a] by hand for M_p = 12 kg, I_p = 0.6 kg m², I_r = 0.01 kg m², r = 0.04 m, L_r = 0.2 m:
    a = 3 I_r/(2 r²) = 0.03/0.0032 = 9.375, m1 = M_p + a = 21.375, m3 = I_p + 3 I_r L_r²/r² = 0.6 + 0.75 = 1.35."""
    theta = np.array([21.375, 1.35, 9.375])
    model = OmniRobot(OmniRobotParameters(mass=12.0, body_inertia=0.6, wheel_inertia=0.01, wheel_radius=0.04,
                                          wheel_distance=0.2))
    loop = single_face_loop("ce", mode=Mode.MACHINE, model=model, wish=(0.5, 3.0, 0.3))
    trace = simulate(loop, [0.0, 2.0, 0.0], [0.0, 0.0, 0.0], 2.0, DT)
    theta_hat = trace.theta_hat[-1]
    assert np.linalg.norm(theta_hat) > 0.1, "θ̂ never moved: the case would test nothing"
    expected = np.linalg.norm(theta_hat - theta) / np.linalg.norm(theta)
    assert summarize(trace, DT)["theta_error"] == pytest.approx(expected, rel=1e-12)


def test_theta_error_is_none_where_theta_is_unknown():
    trace = hand_trace([HUMAN], [[0.0] * 3], [[0.0] * 3], theta_hat=[[1.0, 2.0, 3.0]], theta=None)
    assert summarize(trace, DT)["theta_error"] is None


# ----- input and torque sizes, machine authority time ---------------------------------------------
#: rows with norms 5 (3-4-0), 13 (5-12-0), 0, and a NaN row that every figure skips
FORCES = [[3.0, -4.0, 0.0], [5.0, 0.0, 12.0], [0.0, 0.0, 0.0], [np.nan, 1.0, 0.0]]


def test_peak_norm_is_the_largest_row_norm_skipping_nan_rows():
    assert peak_norm(np.array(FORCES)) == 13.0


def test_rms_norm_is_the_root_mean_square_of_the_row_norms_skipping_nan_rows():
    assert rms_norm(np.array(FORCES)) == pytest.approx(np.sqrt((25.0 + 169.0 + 0.0) / 3), rel=1e-15)


def test_share_above_counts_the_rows_with_some_component_over_the_limit():
    # |components| > 4.5: row 1 (12 and 5) only; row 0's largest is 4; the NaN row is not a sample
    assert share_above(np.array(FORCES), 4.5) == pytest.approx(1 / 3, abs=1e-15)
    assert share_above(np.array(FORCES), 4.0) == pytest.approx(1 / 3, abs=1e-15)   # 4 is not above 4
    assert share_above(np.array(FORCES), 3.9) == pytest.approx(2 / 3, abs=1e-15)


def test_sizes_are_none_without_a_finite_sample():
    empty = np.full((2, 3), np.nan)
    assert (peak_norm(empty), rms_norm(empty), share_above(empty, 1.0)) == (None,) * 3


def test_machine_authority_time_counts_only_full_machine_authority():
    trace = hand_trace([HUMAN, MACHINE, SHARED, MACHINE, MACHINE, HUMAN], [[0.0] * 3] * 6, [[0.0] * 3] * 6)
    assert machine_authority_time(trace, 0.002) == pytest.approx(3 * 0.002, abs=1e-15)
