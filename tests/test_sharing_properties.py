"""The sharing law (paper (46)–(47), sharedctl/sharing.py), against oracles that do not share its code.

* transparency, measured: a run whose state stays more than b2 from every face (so in O_s at any
  speed, by Definition 2) gives the operator authority on every sample, applies u_h value for
  value, and moves the plant exactly as the operator alone would (an RK4 integration written
  here); and `shared_input` under HUMAN authority returns u_h, not u_f;
* the arbiter's decisions on states whose Definition-2 class is computed by hand, on the single
  face y ≤ 4 (row value x = y − 4, rate ẋ = ẏ; f_b(x) = 1/(x + b) − 1/b, the default bands
  b0 = 0.025, b1 = 0.3, b2 = 0.6): full machine authority in the hazardous set, the Schmitt
  trigger (the operator loses authority only in O_d, regains it only in O_s), and the minimum
  dwell Δt (the machine keeps authority for Δt after taking over even in O_s: near a face the
  machine's first push puts the state straight back in O_s, and without a dwell the literal law
  switches at the sample rate — Theorem 5 assumes a Δt > 0 between switches);
* the hand-over: while the operator's push lasts, the machine keeps full authority outside O_d too
  (k_h stays exactly 0, u_s = u_f); once it has turned away (push_away) authority returns at the
  first sample after Δt, and before that the blend follows its closed form from the reset k_h = 0,
  k_h = 1 − e^{−N dt/τ} after N samples; the O_s release holds whatever the push;
* on closed-loop runs (the paper scenarios, random sets, the chattering measurement), the
  properties that need no classification of the state: take-overs only within b1 of the border,
  releases only after Δt, and the number of interventions bounded by Δt.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parent))
import strategies as S

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.scenario import parse
from sharedctl.sets import Bands, SetClass, Situation
from sharedctl.sharing import (
    ArbiterState,
    Authority,
    Decision,
    LawRole,
    SharingParameters,
    arbitrate,
    shared_input,
)
from sharedctl.simulator import simulate

HUMAN, SHARED, MACHINE = int(Authority.HUMAN), int(Authority.SHARED), int(Authority.MACHINE)
PAPER_RUNS = [(name, c) for name in ("paper_convex", "paper_nonconvex") for c in S.CONTROLLERS]


def paper_run(name, controller):
    case = S.paper_case(name)
    return case, S.run(case, controller)


# ----- transparency, measured on a simulated trajectory -----------------------------------------
INSIDE_DT, INSIDE_DURATION = 2e-3, 3.0


def inside_scenario(controller):
    """The paper's convex set (x ≥ −1, 0.5 ≤ y ≤ 4, |ψ| < π/2); the operator (scripted spring)
    follows a line from (−0.2, 2, 0) at (0.1, 0.15, 0.1) for 3 s, starting 0.15 m behind it:
    the wish stays ≥ 0.8 m from x = −1, ≥ 1.5 m from y = 0.5 and y = 4, ≥ 1.2 rad from |ψ| = π/2."""
    data = {
        "name": "transparency-inside", "duration": INSIDE_DURATION, "dt": INSIDE_DT,
        "robot": {"kind": "omni3"},
        "region": [{"K": [[-1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1]],
                    "T": [-1, 0.5, -4, -math.pi / 2, -math.pi / 2]}],
        "initial": {"q": [-0.2, 1.85, 0.0], "qdot": [0.0, 0.0, 0.0]},
        "desired": {"kind": "line", "start": [-0.2, 2.0, 0.0], "velocity": [0.1, 0.15, 0.1]},
        "human": {"kind": "scripted", "kp": 20.0, "kd": 12.0},
    }
    return parse(data).closed_loop(controller)


def operator_alone(loop, q0, v0, steps, dt):
    """The plant driven by u_h alone: classical RK4 on (q, q̇) with the operator's force at every stage."""
    model, human = loop.model, loop.human

    def rate(t, q, v):
        u_h = human.command_from(t, human.desired(t), q, v).force
        return v, model.acceleration(q, v, u_h)

    q, v = np.array(q0, float), np.array(v0, float)
    path = [q]
    for k in range(steps - 1):
        t = k * dt
        a1, b1 = rate(t, q, v)
        a2, b2 = rate(t + dt / 2, q + dt / 2 * a1, v + dt / 2 * b1)
        a3, b3 = rate(t + dt / 2, q + dt / 2 * a2, v + dt / 2 * b2)
        a4, b4 = rate(t + dt, q + dt * a3, v + dt * b3)
        q, v = q + dt / 6 * (a1 + 2 * a2 + 2 * a3 + a4), v + dt / 6 * (b1 + 2 * b2 + 2 * b3 + b4)
        path.append(q)
    return np.array(path)


@pytest.mark.parametrize("controller", S.CONTROLLERS)
def test_transparency_holds_on_a_trajectory_that_stays_inside(controller):
    loop, q0, v0 = inside_scenario(controller)
    trace = simulate(loop, q0, v0, INSIDE_DURATION, INSIDE_DT)
    steps = int(round(INSIDE_DURATION / INSIDE_DT))
    assert trace.t.size == steps
    # the state is in O_s by Definition 2 at any speed: every row more than b2 = 0.6 from its face
    x, y, psi = trace.q.T
    slack = np.min([x + 1.0, y - 0.5, 4.0 - y, math.pi / 2 - np.abs(psi)], axis=0)
    assert slack.min() > 0.6
    # k_s = 1 on every sample: operator authority, k_h = 1, k_f = 0
    assert np.all(trace.authority == HUMAN)
    assert np.all(trace.k_h == 1.0) and np.all(trace.k_f == 0.0)
    # u_s = u_h, value for value, with u_h recomputed from the operator model at the sampled state
    u_h = np.array([loop.human.command_from(t, loop.human.desired(t), q, v).force
                    for t, q, v in zip(trace.t, trace.q, trace.v)])
    assert np.abs(u_h).max() > 1.0                      # the operator does push
    assert np.array_equal(trace.u_s, u_h)
    # and the plant moved exactly as under the operator alone
    assert np.allclose(trace.q, operator_alone(loop, q0, v0, steps, INSIDE_DT), rtol=0.0, atol=1e-9)


def hand_situation(overall: SetClass) -> Situation:
    """A one-polytope situation with no hazardous row (shared_input reads only the decision's weights)."""
    return Situation(overall, (0,), {0: overall}, {0: ()})


def test_shared_input_under_operator_authority_is_u_h_not_u_f():
    u_h, u_f = np.array([1.5, -2.0, 0.25]), np.array([-7.0, 3.0, 9.0])
    decision = Decision(Authority.HUMAN, None, LawRole.TRACKING, 1.0, 0.0, hand_situation(SetClass.SAFE), False, False)
    u_s = shared_input(decision, u_h.copy(), u_f.copy())
    assert np.array_equal(u_s, [1.5, -2.0, 0.25])
    assert not np.array_equal(u_s, u_f)


def test_shared_input_under_machine_authority_is_u_f_not_u_h():
    u_h, u_f = np.array([1.5, -2.0, 0.25]), np.array([-7.0, 3.0, 9.0])
    decision = Decision(Authority.MACHINE, 0, LawRole.HAZARD, 0.0, 1.0, hand_situation(SetClass.HAZARD), False, False)
    u_s = shared_input(decision, u_h.copy(), u_f.copy())
    assert np.array_equal(u_s, [-7.0, 3.0, 9.0])
    assert not np.array_equal(u_s, u_h)


def test_shared_input_in_the_shared_state_blends_by_k_h():
    # k_h = 0.25: u_s = 0.25·(4, 8, −2) + 0.75·(−8, 0, 4) = (1 − 6, 2 + 0, −0.5 + 3) = (−5, 2, 2.5)
    decision = Decision(Authority.SHARED, 0, LawRole.HAZARD, 0.25, 0.75, hand_situation(SetClass.HYSTERESIS),
                        False, False)
    u_s = shared_input(decision, np.array([4.0, 8.0, -2.0]), np.array([-8.0, 0.0, 4.0]))
    assert np.array_equal(u_s, [-5.0, 2.0, 2.5])


# ----- decisions on hand-classified states: the single face y ≤ 4 -------------------------------
FACE = FeasibleSet.from_regions([Polytope.from_rows([[0.0, 1.0, 0.0]], [-4.0])])   # completed far in x and ψ
DT = 1.0 / 64.0                  # exact in binary: 16 samples are exactly Δt = 0.25 s
TAU = 0.25                       # blend time constant: 16 samples are exactly one τ
PARAMS = SharingParameters(blend_time_constant=TAU, min_machine_dwell=0.25)
INTENT = 2.0                     # v_h (reported; the hand-over does not depend on it)

# (row value x = y − 4, rate ẋ = ẏ) and the class by hand, default bands b0 = 0.025, b_s = 0.15, b1 = 0.3,
# b2 = 0.6
SAFE_NEAR = (-0.25, 1.0)         # f_b2(−0.25) = 1/0.35 − 1/0.6 = 2.857 − 1.667 = 1.190 ≥ 1        → O_s
SAFE_FAR = (-1.0, 100.0)         # x < −b2: no allowance applies, any speed                      → O_s
SAFE_RECEDING = (-0.25, -0.5)    # moving away from the face, outside the standoff band b_s        → O_s
STANDOFF_REST = (-0.05, 0.0)     # at rest ε = 0.05 from the face: not an approach, in b_s         → O_h
STANDOFF_RECEDING = (-0.015625, -0.5)  # inside b0, moving away: no approach, in b_s              → O_h
HYSTERESIS_NEAR = (-0.25, 5.0)   # f_b2(−0.25) = 1.190 < 5 < f_b1(−0.25) = 1/0.05 − 1/0.3 = 20 − 3.333 = 16.667
HYSTERESIS_FAR = (-0.5, 9.0)     # x < −b1 (never hazardous); f_b2(−0.5) = 1/0.1 − 1/0.6 = 8.333 < 9
HAZARD_FAST = (-0.25, 20.0)      # 20 ≥ f_b1(−0.25) = 16.667                                      → O_d
HAZARD_INNER = (-0.015625, 0.01)  # f_b1(−0.015625) = 1/0.284375 − 3.333 = 0.183 > 0.01, but
#                                   −b0 ≤ x < 0 and ẋ > 0: the inner band                         → O_d
OUTSIDE = (0.0625, 0.0)          # y = 4.0625 > 4: no polytope contains q                           → O_d


def state(row):
    x, rate = row
    return np.array([0.0, 4.0 + x, 0.0]), np.array([0.0, rate, 0.0])


def decide(arbiter, row, intent=INTENT, params=PARAMS, push_away=False):
    q, v = state(row)
    return arbitrate(FACE, params, arbiter, q, v, intent, DT, lambda g: 0.0, push_away=push_away)


def run_sequence(rows, intent=INTENT, params=PARAMS, arbiter=None, push_away=False):
    """Feed the arbiter the states in order (with the push turned away or not: one flag, or one per
    state); return the decisions and the last arbiter state."""
    arbiter = ArbiterState() if arbiter is None else arbiter
    flags = push_away if isinstance(push_away, list) else [push_away] * len(rows)
    decisions = []
    for row, flag in zip(rows, flags):
        arbiter, decision = decide(arbiter, row, intent, params, flag)
        decisions.append(decision)
    return decisions, arbiter


@pytest.mark.parametrize("row", [SAFE_NEAR, SAFE_FAR, SAFE_RECEDING], ids=["near", "far", "receding"])
def test_safe_states_leave_the_operator_in_charge(row):
    (decision,), _ = run_sequence([row])
    assert decision.authority is Authority.HUMAN
    assert (decision.k_h, decision.k_f) == (1.0, 0.0)


@pytest.mark.parametrize("row", [HAZARD_FAST, HAZARD_INNER, OUTSIDE], ids=["fast", "inner-band", "outside"])
def test_hazardous_states_give_the_machine_full_authority(row):
    (before, decision), _ = run_sequence([SAFE_NEAR, row])
    assert before.authority is Authority.HUMAN
    assert decision.authority is Authority.MACHINE
    assert (decision.k_h, decision.k_f) == (0.0, 1.0)
    assert decision.role is LawRole.HAZARD


def test_an_approach_inside_the_inner_band_is_left_to_the_operator_without_b0():
    """Definition 2 as printed (b0 = 0): HAZARD_INNER is below both allowances
    (f_b2(−0.015625) = 1/0.584375 − 1/0.6 = 1.7112 − 1.6667 = 0.0446 > 0.01), so it is safe."""
    printed = SharingParameters(bands=Bands(b0=0.0), blend_time_constant=TAU, min_machine_dwell=0.25)
    (decision,), _ = run_sequence([HAZARD_INNER], params=printed)
    assert decision.authority is Authority.HUMAN


def test_the_operator_keeps_authority_in_the_hysteresis_set():
    """k_s holds 1 from O_s through O_h: authority changes only on entering O_d."""
    decisions, _ = run_sequence([SAFE_NEAR, HYSTERESIS_NEAR, HYSTERESIS_FAR, HYSTERESIS_NEAR, HAZARD_FAST])
    assert [d.authority for d in decisions] == [Authority.HUMAN] * 4 + [Authority.MACHINE]


def test_the_machine_keeps_full_authority_in_the_hysteresis_set_while_the_push_lasts():
    """k_s holds 0 from O_d through O_h and k_h stays exactly 0: u_s = u_f, however long."""
    decisions, _ = run_sequence([HAZARD_FAST] + [HYSTERESIS_FAR, HYSTERESIS_NEAR, STANDOFF_REST] * 40)
    assert all(d.authority is Authority.MACHINE and d.k_h == 0.0 for d in decisions)
    u_f = np.array([3.0, -4.0, 1.0])
    assert np.array_equal(shared_input(decisions[-1], np.array([50.0, 0.0, 0.0]), u_f), u_f)


def test_the_standoff_band_is_not_safe_so_resting_there_does_not_hand_authority_back():
    decisions, _ = run_sequence([HAZARD_FAST] + [STANDOFF_REST, STANDOFF_RECEDING] * 40)
    assert all(d.situation.overall is SetClass.HYSTERESIS for d in decisions[1:])
    assert all(d.authority is Authority.MACHINE for d in decisions)


def test_the_safe_set_returns_authority_only_after_the_minimum_dwell():
    """Take-over at sample 0, then O_s with the push still on: 15 more samples (15/64 s < Δt = 0.25 s)
    stay with the machine, the 16th (16/64 s = Δt) hands authority back — O_s releases whatever the push."""
    decisions, _ = run_sequence([HAZARD_FAST] + [SAFE_NEAR] * 20)
    authority = [d.authority for d in decisions]
    assert authority[1:16] == [Authority.MACHINE] * 15
    assert authority[16:] == [Authority.HUMAN] * 5


def test_without_a_dwell_the_first_safe_sample_hands_authority_back():
    literal = SharingParameters(blend_time_constant=TAU, min_machine_dwell=0.0)
    decisions, _ = run_sequence([HAZARD_FAST, SAFE_NEAR], params=literal)
    assert [d.authority for d in decisions] == [Authority.MACHINE, Authority.HUMAN]


def test_each_take_over_and_release_counts_one_switch():
    _, arbiter = run_sequence([SAFE_NEAR, HAZARD_FAST] + [SAFE_NEAR] * 16 + [HYSTERESIS_NEAR, HAZARD_FAST])
    assert arbiter.switches == 3      # take-over, release after Δt, take-over


def test_a_push_that_turns_away_gets_authority_back_at_the_first_sample_after_the_dwell():
    """Take-over, 40 samples at rest in the standoff band with the push on, then the push turns away:
    the very next sample is the operator's (the dwell, 16 samples, is long past)."""
    flags = [False] * 41 + [True] * 3
    decisions, arbiter = run_sequence([HAZARD_FAST] + [STANDOFF_REST] * 43, push_away=flags)
    assert [d.authority for d in decisions[40:]] == [Authority.MACHINE, Authority.HUMAN, Authority.HUMAN,
                                                      Authority.HUMAN]
    assert arbiter.switches == 2


def test_a_push_that_turns_away_within_the_dwell_waits_for_it_and_blends_meanwhile():
    """Push away from the first sample after the take-over: 15 samples blend (k_h from the reset 0 towards
    1 with τ = 16 samples: k_h = 1 − e^{−N/16}), the 16th releases."""
    decisions, _ = run_sequence([HAZARD_FAST] + [STANDOFF_REST] * 17, push_away=[False] + [True] * 17)
    assert all(d.authority is Authority.SHARED for d in decisions[1:16])
    assert decisions[8].k_h == pytest.approx(1.0 - math.exp(-0.5), rel=1e-12)        # 0.3934693402873666
    assert decisions[15].k_h == pytest.approx(1.0 - math.exp(-15 / 16), rel=1e-12)
    assert decisions[16].authority is Authority.HUMAN
    # applied: u_s = k_h·(10, 0, 0) + k_f·(0, −20, 0) with k_h = 0.3934693402873666
    u_s = shared_input(decisions[8], np.array([10.0, 0.0, 0.0]), np.array([0.0, -20.0, 0.0]))
    assert u_s == pytest.approx([3.934693402873666, -12.130613194252668, 0.0], rel=1e-12)


def test_a_turned_away_push_never_releases_a_hazardous_state():
    decisions, _ = run_sequence([HAZARD_FAST] * 40 + [HAZARD_INNER] * 40, push_away=True)
    assert all(d.authority is Authority.MACHINE and d.k_h == 0.0 for d in decisions)


def test_the_operator_weight_restarts_from_zero_after_a_new_hazard():
    """8 samples of blending (k_h = 1 − e^{−1/2}), a hazardous sample (k_h = 0), then one hysteresis
    sample: k_h = 1 − e^{−1/16} = 0.06058693718652419."""
    rows = [HAZARD_FAST] + [STANDOFF_REST] * 8 + [HAZARD_FAST, STANDOFF_REST]
    decisions, _ = run_sequence(rows, push_away=[False] + [True] * 10)
    assert decisions[-2].authority is Authority.MACHINE and decisions[-2].k_h == 0.0
    assert decisions[-1].k_h == pytest.approx(0.06058693718652419, rel=1e-12)


# ----- closed-loop runs: the paper scenarios (same runs as the invariance tests) -----------------
@pytest.mark.parametrize("name,controller", PAPER_RUNS)
def test_paper_runs_take_over_only_within_b1_of_the_border(name, controller):
    case, trace = paper_run(name, controller)
    assert S.takeover_samples(trace).size > 0
    loop = case.loop(controller)
    assert S.takeover_margin_failures(trace, case.sharing, loop.backup, loop.model) == []


@pytest.mark.parametrize("name,controller", PAPER_RUNS)
def test_paper_runs_switch_at_most_twice_per_excursion_of_the_wish_and_release_only_after_the_dwell(
        name, controller):
    """The wish is outside the set once in the shortened runs (counted here from the recorded
    admissibility): one take-over and at most one release follow it, none before it."""
    case, trace = paper_run(name, controller)
    outside = ~trace.wish_inside
    starts = np.concatenate([[0] if outside[0] else [], np.flatnonzero(outside[1:] & ~outside[:-1]) + 1])
    changes = np.sort(np.concatenate([S.takeover_samples(trace), S.release_samples(trace)]))
    assert starts.size == 1
    assert changes.size >= 1 and changes[0] >= starts[0] and changes.size <= 2
    assert S.dwell_failures(trace, case.sharing, S.DT) == []


@pytest.mark.parametrize("name,controller", PAPER_RUNS)
def test_interventions_are_bounded_by_the_minimum_dwell(name, controller):
    """Every intervention lasts ≥ Δt, so at most duration/Δt + 1 of them fit in a run; the
    arbiter's switch counter agrees with the trace (one take-over + one release each)."""
    case, trace = paper_run(name, controller)
    takeovers, releases = S.takeover_samples(trace).size, S.release_samples(trace).size
    assert takeovers <= case.duration / case.sharing.min_machine_dwell + 1
    assert trace.switches == takeovers + releases


# ----- the same on random sets and adversarial operators ----------------------------------------
@settings(max_examples=3, **S.SIM_SETTINGS)
@given(case=st.one_of(S.convex_cases, S.union_cases, S.adversarial_cases), controller=S.controllers)
def test_sharing_properties_hold_on_random_sets(case, controller):
    trace = S.run(case, controller)
    loop = case.loop(controller)
    assert S.sharing_failures(trace, case.sharing, S.DT, loop.backup, loop.model) == [], \
        S.describe(case, controller, trace)


# ----- no chattering ---------------------------------------------------------------------------
PUSH = S.push_case(100.0, 2.0)


NO_STANDOFF = Bands(standoff=Bands().b0)


def interventions(dt, dwell, bands=NO_STANDOFF, hold=True):
    """Take-overs of the push run; by default without the standoff band (b_s = b0), where the machine's
    rest point ε inside the face is safe and the Schmitt trigger alone decides; `hold`: the machine keeps
    authority while the push heads at a face hazardous since its take-over (False: the safe set releases)."""
    sharing = SharingParameters(bands=bands, min_machine_dwell=dwell, hold_pushed_faces=hold)
    trace = S.run(PUSH, "ce", dt=dt, sharing=sharing)
    assert S.invariance_failure(PUSH, "ce", trace, dt=dt) is None
    return S.takeover_samples(trace).size


def test_switch_count_does_not_grow_when_the_sample_rate_doubles():
    """An operator leaning on a face with 100 N for 2 s (ce law). With the dwell, halving dt
    changes the number of interventions by at most max(2, 25 %): sampling shifts the instant
    each approach is caught by the hazard test, so a marginal re-approach can be caught in
    one run and not in the other — a chattering law would instead double its count."""
    coarse, fine = interventions(2e-3, 0.25), interventions(1e-3, 0.25)
    assert coarse <= PUSH.duration / 0.25 + 1
    assert fine <= coarse + max(2, 0.25 * coarse)


def test_literal_law_without_dwell_chatters_more_as_the_sample_rate_grows():
    """The measurement that justifies min_machine_dwell: the printed law (Δt = 0) on the same
    run intervenes many times more often than with the dwell, and more again at dt/2 —
    the count follows the sample rate (Zeno behaviour in continuous time). Both release in the safe
    set whatever the push, as Theorem 5's claim 3 reads."""
    with_dwell = interventions(2e-3, 0.25, hold=False)
    literal_coarse, literal_fine = interventions(2e-3, 0.0, hold=False), interventions(1e-3, 0.0, hold=False)
    assert literal_coarse >= 5 * with_dwell
    assert literal_fine >= 1.25 * literal_coarse


def test_holding_authority_while_the_push_heads_at_the_face_takes_over_once_even_without_dwell_and_band():
    """The same lean with the printed trigger (no standoff band, no dwell) but the hold of
    docs/control.md §6: the machine does not hand the robot back into a push at the face it took over
    at, so the operator leaning on it meets one take-over, at dt and at dt/2."""
    assert interventions(2e-3, 0.0) == 1
    assert interventions(1e-3, 0.0) == 1


def test_with_the_standoff_band_a_lean_on_a_face_settles_after_at_most_one_rebound():
    """The same 100 N lean, now with the standoff band: the impact's rebound may carry the robot back
    out of the band once (one release, one more take-over), then the machine holds it at rest for as
    long as the push lasts — the count is the same at dt and dt/2, with the dwell or without it, and
    after 2 s or 6 s of pushing: no pulse train."""
    def count(dt, dwell, case):
        trace = S.run(case, "ce", dt=dt, sharing=SharingParameters(bands=Bands(), min_machine_dwell=dwell))
        assert S.invariance_failure(case, "ce", trace, dt=dt) is None
        return S.takeover_samples(trace).size

    counts = [count(dt, dwell, case) for case in (PUSH, S.push_case(100.0, 6.0))
              for dt in (2e-3, 1e-3) for dwell in (0.25, 0.0)]
    assert 1 <= counts[0] <= 2 and counts == [counts[0]] * 8
