"""Definition 2 (sharedctl/sets.py) at points whose class is worked out by hand.

f_b(x) = 1/(x + b) − 1/b. A row is hazardous when −b1 ≤ x < 0 and ẋ ≥ f_b1(x), or −b0 ≤ x < 0
and ẋ > 0 (the inner band); unsafe when x ≥ −b2 and ẋ > f_b2(x) (f_b = +∞ for x ≤ −b). A polytope
is HAZARD with a hazardous row, HYSTERESIS with an unsafe one, SAFE otherwise; a union is SAFE if
some polytope containing q is, HAZARD if every one is (or none contains q), HYSTERESIS otherwise.

Each entry point is checked against the hand value: `classify_rows` (one polytope's rows),
`classify_groups` (every group at once) and `classify` (the union, with the containing regions).
The single-row table uses the bands b1 = 1/4, b2 = 1/2, b0 = 1/16, for which the band edges and
the allowance curves at the chosen points are exact binary numbers, so "on the curve" and "one
float past it" are meant literally.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.services.scenario_files import load
from sharedctl.sets import Bands, SetClass, classify, classify_groups, classify_rows

SAFE, HYSTERESIS, HAZARD = SetClass.SAFE, SetClass.HYSTERESIS, SetClass.HAZARD
# f_b1(x) = 1/(x + 1/4) − 4, f_b2(x) = 1/(x + 1/2) − 2; the standoff band as wide as the inner band
DYADIC = Bands(b1=0.25, b2=0.5, b0=0.0625, standoff=0.0625)
HALF_LINE = FeasibleSet.from_regions([Polytope.from_rows([[1.0]], [0.0])])   # {x ≤ 0}: q = [x], one row, one group
TINY = 2.0**-20
BELOW_FOUR = math.nextafter(4.0, -math.inf)

# (x, ẋ, class of the row) — worked out by hand with DYADIC
ROWS = [
    (-0.125, 4.0, HAZARD),               # f_b1(−1/8) = 1/(1/8) − 4 = 8 − 4 = 4: on the curve, ẋ ≥ f_b1
    (-0.125, BELOW_FOUR, HYSTERESIS),    # one float below f_b1 = 4; above f_b2(−1/8) = 1/(3/8) − 2 = 0.667
    (-0.125, 0.5, SAFE),                 # 0.5 ≤ f_b2(−1/8) = 0.667
    (-0.125, math.inf, HAZARD),          # ∞ ≥ 4
    (-0.125, -math.inf, SAFE),           # moving away at any speed
    (-0.25, 2.0, SAFE),                  # x = −b1: f_b2(−1/4) = 1/(1/4) − 2 = 2, on the curve, not above it
    (-0.25, math.nextafter(2.0, math.inf), HYSTERESIS),   # one float above f_b2; f_b1(−b1) = +∞
    (-0.25, 1e300, HYSTERESIS),          # x = −b1: in the hazard band, but f_b1(−b1) = +∞
    (-0.5, 1e300, SAFE),                 # x = −b2: f_b2(−b2) = +∞, no speed is unsafe there
    (-1.0, 1e300, SAFE),                 # beyond b2
    (-math.inf, 5.0, SAFE),              # infinitely far inside
    (-0.0625, TINY, HAZARD),             # x = −b0: any approach, 2⁻²⁰ < f_b2(−1/16) = 1/(7/16) − 2 = 0.286
    (-0.0625, 0.0, SAFE),                # at rest on −b0: not an approach; 0 ≤ f_b2 = 0.286
    (-0.0625, -0.0, SAFE),
    (math.nextafter(-0.0625, -math.inf), TINY, SAFE),     # one float outside b0: 2⁻²⁰ < f_b2 ≈ 0.286
    (0.0, 0.0, HYSTERESIS),              # on the face, at rest: not hazardous (x < 0 fails), in the standoff band
    (0.0, TINY, HYSTERESIS),             # on the face, moving out: ẋ > f_b2(0) = 0
]


def row_id(row):
    return f"x={row[0]!r},xdot={row[1]!r}"


@pytest.mark.parametrize("x,x_dot,expected", ROWS, ids=[row_id(r) for r in ROWS])
def test_one_row_has_the_class_computed_by_hand(x, x_dot, expected):
    assert classify_rows(np.array([x]), np.array([x_dot]), DYADIC) is expected


@pytest.mark.parametrize("x,x_dot,expected", ROWS, ids=[row_id(r) for r in ROWS])
def test_the_group_of_one_row_has_the_class_computed_by_hand(x, x_dot, expected):
    assert classify_groups(HALF_LINE, np.array([x]), np.array([x_dot]), DYADIC) == (expected,)


@pytest.mark.parametrize("x,x_dot,expected", ROWS, ids=[row_id(r) for r in ROWS])
def test_the_half_line_has_the_row_class_inside_and_is_hazardous_on_or_past_its_face(x, x_dot, expected):
    """q = [x] is inside {x ≤ 0} (strictly) only for x < 0; on the face no polytope contains it."""
    situation = classify(HALF_LINE, np.array([x]), np.array([x_dot]), DYADIC)
    if x < 0.0:
        assert situation.overall is expected
        assert situation.containing == (0,) and situation.region_class == {0: expected}
        assert situation.hazard_rows == {0: (0,) if expected is HAZARD else ()}
    else:
        assert situation.overall is HAZARD and situation.containing == ()


@pytest.mark.parametrize("x", [0.0625, math.inf, math.nan])
def test_a_state_outside_every_polytope_is_hazardous(x):
    assert classify(HALF_LINE, np.array([x]), np.array([0.0]), DYADIC).overall is HAZARD


def test_the_printed_definition_leaves_an_inner_band_approach_safe():
    """b0 = 0 (Definition 2 as printed): x = −1/16, ẋ = 2⁻²⁰ is below f_b2(−1/16) = 0.286."""
    printed = Bands(b1=0.25, b2=0.5, b0=0.0, standoff=0.0)
    assert classify_rows(np.array([-0.0625]), np.array([TINY]), printed) is SAFE


def test_the_printed_definition_leaves_a_state_at_rest_on_the_face_safe():
    """b0 = b_s = 0: x = 0, ẋ = 0 — 0 > f_b2(0) = 2 − 2 = 0 fails, so the row is not unsafe."""
    printed = Bands(b1=0.25, b2=0.5, b0=0.0, standoff=0.0)
    assert classify_rows(np.array([0.0]), np.array([0.0]), printed) is SAFE


STANDOFF = Bands(b1=0.25, b2=0.5, b0=0.0625, standoff=0.1875)   # b_s = 3/16
# (x, ẋ, class) with STANDOFF, by hand: inside the band (x > −3/16) nothing is safe
STANDOFF_ROWS = [
    (-0.125, 0.0, HYSTERESIS),            # at rest 1/8 from the face: in the band (printed: safe)
    (-0.125, -5.0, HYSTERESIS),           # moving away, still in the band
    (-0.125, 4.0, HAZARD),                # on f_b1(−1/8) = 4: hazardous, band or not
    (-0.0625, TINY, HAZARD),              # the inner band's approach
    (-0.1875, 0.0, SAFE),                 # on the band's edge: x > −b_s fails; 0 ≤ f_b2(−3/16) = 1.2
    (math.nextafter(-0.1875, 0.0), 0.0, HYSTERESIS),   # one float inside the band
    (-0.25, 0.0, SAFE),
]


@pytest.mark.parametrize("x,x_dot,expected", STANDOFF_ROWS, ids=[row_id(r) for r in STANDOFF_ROWS])
def test_no_row_in_the_standoff_band_is_safe(x, x_dot, expected):
    assert classify_rows(np.array([x]), np.array([x_dot]), STANDOFF) is expected
    assert classify_groups(HALF_LINE, np.array([x]), np.array([x_dot]), STANDOFF) == (expected,)
    assert classify(HALF_LINE, np.array([x]), np.array([x_dot]), STANDOFF).overall is expected


def test_bands_refuse_a_standoff_band_outside_b0_to_b1():
    with pytest.raises(ValueError, match="standoff"):
        Bands(b1=0.3, b2=0.6, b0=0.025, standoff=0.02)
    with pytest.raises(ValueError, match="standoff"):
        Bands(b1=0.3, b2=0.6, b0=0.025, standoff=0.3)


# ----- the paper's sets, bands b0 = 0.025, b1 = 0.3, b2 = 0.6, no standoff beyond b0 ---------------
def paper_set(name):
    return load(name).closed_loop("ce")[0].feasible


BANDS = Bands(standoff=0.025)


def test_convex_set_near_the_top_face_moving_up_is_hazardous_only_in_groups_holding_that_face():
    """q = (−0.9, 3.97, 0), q̇ = (0, 0.5, 0) in x ≥ −1, 0.5 ≤ y ≤ 4, |ψ| < π/2 (rows 0–4:
    −x − 1, 0.5 − y, y − 4, ψ − π/2, −ψ − π/2). Row 2: x = −0.03, ẋ = 0.5 ≥ f_b1(−0.03) =
    1/0.27 − 1/0.3 = 3.7037 − 3.3333 = 0.370: hazardous. Row 0: x = −0.1 at rest, 0 ≤ f_b2(−0.1) =
    1/0.5 − 1/0.6 = 0.333: safe; rows 1, 3, 4 are beyond b2."""
    feasible = paper_set("paper_convex")
    q, v = np.array([-0.9, 3.97, 0.0]), np.array([0.0, 0.5, 0.0])
    expected = tuple(HAZARD if 2 in g.rows else SAFE for g in feasible.groups)
    assert HAZARD in expected and SAFE in expected
    assert classify_groups(feasible, q, v, BANDS) == expected
    situation = classify(feasible, q, v, BANDS)
    assert situation.overall is HAZARD and situation.hazard_rows == {0: (2,)}


def test_convex_set_near_the_left_face_moving_left_is_in_the_hysteresis_set():
    """q = (−0.9, 3.97, 0), q̇ = (−0.5, 0, 0). Row 0: x = −0.1, ẋ = 0.5, between f_b2(−0.1) = 0.333
    and f_b1(−0.1) = 1/0.2 − 1/0.3 = 1.667: unsafe, not hazardous. Row 2: x = −0.03 at rest: safe
    (no approach, so the inner band does not apply). Every group holds row 0 (the only x row)."""
    feasible = paper_set("paper_convex")
    q, v = np.array([-0.9, 3.97, 0.0]), np.array([-0.5, 0.0, 0.0])
    assert classify_groups(feasible, q, v, BANDS) == (HYSTERESIS,) * len(feasible.groups)
    assert classify(feasible, q, v, BANDS).overall is HYSTERESIS


def test_convex_groups_with_a_hazardous_row_are_hazardous_whatever_their_other_rows():
    """q = (−0.5, 3.97, 1.2), q̇ = (0, 0.5, 5). Row 2 (y − 4 = −0.03, ẋ = 0.5 ≥ 0.370) is hazardous;
    row 3 (ψ − π/2 = −0.3708, ẋ = 5 > f_b2(−0.3708) = 1/0.2292 − 1/0.6 = 4.363 − 1.667 = 2.696, and
    beyond b1) is unsafe; rows 0 (−0.5 at rest), 1 (−3.47) and 4 (−2.77) are safe. A group holding
    row 2 is HAZARD even when row 3 comes after it; one holding row 3 alone is HYSTERESIS."""
    feasible = paper_set("paper_convex")
    q, v = np.array([-0.5, 3.97, 1.2]), np.array([0.0, 0.5, 5.0])
    expected = tuple(HAZARD if 2 in g.rows else HYSTERESIS if 3 in g.rows else SAFE for g in feasible.groups)
    assert (0, 2, 3) in [g.rows for g in feasible.groups]       # the unsafe row 3 after the hazardous row 2
    assert classify_groups(feasible, q, v, BANDS) == expected
    assert classify(feasible, q, v, BANDS).overall is HAZARD


NONCONVEX_CASES = [
    # q, q̇, class of region 0 = {x ≤ 0}, class of region 1 = {y ≤ 0} (None: q outside it), overall
    # near both faces, moving right at 2 ≥ f_b1(−0.1) = 1.667: hazardous in {x ≤ 0}, safe in {y ≤ 0}
    ((-0.1, -0.1, 0.0), (2.0, 0.0, 0.0), HAZARD, SAFE, SAFE),
    # also moving up at 1: f_b2(−0.1) = 0.333 < 1 < 1.667 in {y ≤ 0}
    ((-0.1, -0.1, 0.0), (2.0, 1.0, 0.0), HAZARD, HYSTERESIS, HYSTERESIS),
    # moving up at 2 as well: hazardous in both
    ((-0.1, -0.1, 0.0), (2.0, 2.0, 0.0), HAZARD, HAZARD, HAZARD),
    # below the obstacle, only {y ≤ 0} contains q: its class is the union's
    ((0.5, -0.1, 0.0), (0.0, 0.2, 0.0), None, SAFE, SAFE),
    ((0.5, -0.1, 0.0), (0.0, 2.0, 0.0), None, HAZARD, HAZARD),
    # in the obstacle: no polytope contains q
    ((0.5, 0.5, 0.0), (0.0, 0.0, 0.0), None, None, HAZARD),
]


@pytest.mark.parametrize("q,v,region0,region1,overall", NONCONVEX_CASES)
def test_nonconvex_union_is_safe_in_some_polytope_and_hazardous_only_in_all(q, v, region0, region1, overall):
    feasible = paper_set("paper_nonconvex")
    situation = classify(feasible, np.array(q), np.array(v), BANDS)
    assert situation.overall is overall
    expected_regions = {r: c for r, c in ((0, region0), (1, region1)) if c is not None}
    assert situation.region_class == expected_regions


def test_nonconvex_groups_are_classified_whether_or_not_their_polytope_contains_q():
    """q = (0.5, −0.1, 0) at rest: {x ≤ 0}'s row is x = 0.5 (outside; 0 > f_b2(0.5) = 1/1.1 − 1/0.6 =
    0.909 − 1.667 = −0.758: unsafe), {y ≤ 0}'s is −0.1 at rest (safe)."""
    feasible = paper_set("paper_nonconvex")
    q, v = np.array([0.5, -0.1, 0.0]), np.zeros(3)
    expected = tuple(HYSTERESIS if g.region == 0 else SAFE for g in feasible.groups)
    assert classify_groups(feasible, q, v, BANDS) == expected
