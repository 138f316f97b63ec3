"""The hand-over under an operator who keeps pushing (docs/control.md §6, item 1): the machine that
took over keeps authority while the push heads at a face hazardous since its take-over, so a rush
meets one take-over, not a train of them.

Released whenever the state turned safe (`[sharing] hold_pushed_faces = false`), a rush from afar
met up to 9 take-overs in 6 s under output feedback (the machine's braking made the state safe
1–1.5 m from the face, and the push, still on, made it hazardous again), and an operator at the
console — whose wish is the pose plus half a metre of deflection, admissible far from every face —
up to 13 with any law, at the speed where a stop could turn the robot past its ψ limit. The runs
are the sampled loop of tests/test_fault_envelope_properties.py without faults: random convex sets
and unions, a rush at full deflection towards a point 1 m beyond a face (k_p 20–60 N), 6 s.
"""
from __future__ import annotations

import tomllib
from importlib import resources

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.scenario import ScenarioError, parse
from sharedctl.sets import Bands, SetClass
from sharedctl.sharing import ArbiterState, LawRole, SharingParameters, arbitrate, operator_pushes

from . import strategies as S
from .test_fault_envelope_properties import SETTINGS, Envelope, periods, start

RUSH = 6.0            # s
CONSOLE_REACH = 0.5   # m (rad) at full deflection: the keyboard's and the gamepad's default reach
TAKEOVERS = 2         # at most, per run: one per face (a union's next polytope may bring a second)


def takeovers(law: str, case, seed: int, console: bool):
    run = start(case, law, ("rush", seed), Envelope(seed=seed), console_reach=CONSOLE_REACH if console else None)
    run.run(periods(RUSH))
    return (run.state.arbiter.switches + 1) // 2, run


@pytest.mark.slow
@pytest.mark.parametrize("law", S.CONTROLLERS)
def test_a_rush_at_a_face_meets_one_take_over_per_face(law):
    @settings(max_examples=3, **SETTINGS)
    @given(case=st.one_of(S.convex_cases, S.union_cases), seed=S.seeds, console=st.booleans())
    @example(case=S.random_convex_case(2), seed=2, console=True)      # released into the push: 13 (ce), 15 (of)
    @example(case=S.random_convex_case(2), seed=2, console=False)     # 9 under of
    def check(case, seed, console):
        count, run = takeovers(law, case, seed, console)
        assert 1 <= count <= TAKEOVERS, f"{count} take-overs: " + run.report()
        assert run.min_margin > 0.0, run.report()

    check()


# ----- the rule itself, on one face -----------------------------------------------------------
PSI = ([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], [-np.pi / 2, -np.pi / 2])                  # |ψ| ≤ π/2
WALL = FeasibleSet.from_regions([Polytope.from_rows([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]] + PSI[0],
                                                    [-2.0, -5.0, -5.0] + PSI[1])])     # x ≤ 2, |y| ≤ 5
#: that, and x ≤ 4 for −5 ≤ y ≤ 0: the face x = 2 lies inside the second polytope below y = 0
STEP = FeasibleSet.from_regions([
    Polytope.from_rows([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]] + PSI[0], [-2.0, -5.0, -5.0] + PSI[1]),
    Polytope.from_rows([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]] + PSI[0], [-4.0, 0.0, -5.0] + PSI[1]),
])
DT = 2e-3


def step(feasible, state, q, v, u_h, hold=True, push_away=False):
    params = SharingParameters(hold_pushed_faces=hold)
    v, u_h = np.asarray(v, float), np.asarray(u_h, float)
    return arbitrate(feasible, params, state, np.asarray(q, float), v, 1.0, DT, lambda g: 0.0,
                     push_away=push_away, pushes=operator_pushes(feasible, u_h), push_power=float(v @ u_h))


def taken_over(feasible, q):
    """The state one sample after a take-over at the face x = 2, approached at 1 m/s from q (2 cm from it),
    the dwell over."""
    state, decision = step(feasible, ArbiterState(), q, [1.0, 0.0, 0.0], [20.0, 0.0, 0.0])
    assert decision.situation.overall is SetClass.HAZARD and state.machine_latched
    return ArbiterState(True, state.group, state.role, 0.0, 1.0, state.switches, 0, state.held_rows)


def test_a_push_still_at_the_face_keeps_the_machine_in_the_safe_set_and_a_push_turned_away_gets_it_back():
    state = taken_over(WALL, [1.98, 0.0, 0.0])
    assert state.held_rows == (0,)                    # x ≤ 2: its row, and only it
    safe_q, rest = [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]   # 1 m from the face, at rest: safe
    kept, decision = step(WALL, state, safe_q, rest, [20.0, 5.0, 0.0])
    assert decision.situation.overall is SetClass.SAFE and kept.machine_latched and kept.held_rows == (0,)
    released, _ = step(WALL, state, safe_q, rest, [0.0, 5.0, 0.0])          # along the face: k u_h = 0
    assert not released.machine_latched and released.held_rows == ()
    literal, _ = step(WALL, state, safe_q, rest, [20.0, 5.0, 0.0], hold=False)
    assert not literal.machine_latched


def test_a_push_at_a_held_face_that_lies_inside_another_polytope_is_no_push_out_of_the_set():
    state = taken_over(STEP, [1.98, 1.0, 0.0])
    inside_both = [1.0, -1.0, 0.0]                      # in both polytopes, far from every face, at rest
    released, decision = step(STEP, state, inside_both, [0.0, 0.0, 0.0], [20.0, 0.0, 0.0])
    assert decision.situation.overall is SetClass.SAFE and not released.machine_latched
    kept, _ = step(STEP, state, [1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [20.0, 0.0, 0.0])    # in the first only
    assert kept.machine_latched


def test_a_row_hazardous_only_through_the_stops_reach_is_pushed_by_a_push_that_adds_kinetic_energy():
    """A row farther than b2 from its face (here ψ ≤ π/2 at ψ = 0) is hazardous only through the
    reach of the stop, which grows with the kinetic energy: the machine keeps it while v·u_h > 0."""
    state = ArbiterState(True, 0, LawRole.TRACKING, 0.0, 1.0, 1, 0, (3,))     # held: ψ ≤ π/2 only
    q, v = [0.0, 0.0, 0.0], [0.5, 0.0, 0.0]
    assert Bands().b2 < np.pi / 2
    kept, decision = step(WALL, state, q, v, [-5.0, 10.0, 0.0])      # no push at the row, but v·u_h < 0
    assert decision.situation.overall is SetClass.SAFE and not kept.machine_latched
    kept, _ = step(WALL, state, q, v, [5.0, -10.0, 0.0])             # v·u_h > 0
    assert kept.machine_latched


def test_the_scenario_key_sets_the_rule_and_refuses_anything_but_a_boolean():
    data = tomllib.loads(resources.files("sharedctl").joinpath("scenarios/adversarial_wall.toml").read_text())
    assert parse(data).closed_loop("ce")[0].sharing.hold_pushed_faces
    data.setdefault("sharing", {})["hold_pushed_faces"] = False
    assert not parse(data).closed_loop("ce")[0].sharing.hold_pushed_faces
    data["sharing"]["hold_pushed_faces"] = "no"
    with pytest.raises(ScenarioError, match="hold_pushed_faces"):
        parse(data)
