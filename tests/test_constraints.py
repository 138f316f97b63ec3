"""Constraint sets: completion, group enumeration, margins, applicability."""
import numpy as np
import pytest

from sharedctl.constraints import ConstraintError, FeasibleSet, Polytope

from .helpers import HALF_PI, PAPER_CONVEX_K, PAPER_CONVEX_T


def test_paper_convex_set_has_four_groups():
    fs = FeasibleSet.from_regions([Polytope.from_rows(PAPER_CONVEX_K, PAPER_CONVEX_T)])
    # one x row, one of two y rows, one of two ψ rows
    assert len(fs.groups) == 4
    for g in fs.groups:
        assert abs(np.linalg.det(g.K)) > 0.5


def test_fewer_rows_than_dimensions_are_completed_with_far_rows():
    fs = FeasibleSet.from_regions([Polytope.from_rows([[1, 0, 0]], [0])], completion_distance=500.0)
    region = fs.regions[0]
    assert region.K.shape == (3, 3)
    assert np.linalg.matrix_rank(region.K) == 3
    assert fs.contains(np.array([-1.0, 499.0, -499.0]))
    assert not fs.contains(np.array([-1.0, 501.0, 0.0]))


def test_margin_is_the_best_regions_smallest_slack():
    fs = FeasibleSet.from_regions(
        [Polytope.from_rows([[1, 0, 0], [0, 0, 1], [0, 0, -1]], [0, -HALF_PI, -HALF_PI]),
         Polytope.from_rows([[0, 1, 0], [0, 0, 1], [0, 0, -1]], [0, -HALF_PI, -HALF_PI])]
    )
    assert fs.margin(np.array([-0.5, 3.0, 0.0])) == pytest.approx(0.5)
    assert fs.margin(np.array([2.0, -0.25, 0.0])) == pytest.approx(0.25)
    assert fs.margin(np.array([1.0, 2.0, 0.0])) == pytest.approx(-1.0)
    assert fs.containing_regions(np.array([-1.0, -1.0, 0.0])) == [0, 1]


def test_groups_apply_only_inside_their_polytope():
    fs = FeasibleSet.from_regions(
        [Polytope.from_rows([[1, 0, 0], [0, 0, 1], [0, 0, -1]], [0, -HALF_PI, -HALF_PI]),
         Polytope.from_rows([[0, 1, 0], [0, 0, 1], [0, 0, -1]], [0, -HALF_PI, -HALF_PI])]
    )
    applicable = fs.applicable_groups(np.array([2.0, -1.0, 0.0]))
    assert applicable and all(fs.groups[g].region == 1 for g in applicable)


def test_rows_are_normalised_so_slack_is_a_distance():
    p = Polytope.from_rows([[0, 2, 0]], [-8])   # 2y − 8 ≤ 0  ⇔  y ≤ 4
    assert p.margin(np.array([0.0, 3.0, 0.0])) == pytest.approx(1.0)


@pytest.mark.parametrize(
    "K,T,match",
    [([[1, 0, 0]], [0, 1], "rows"), ([[0, 0, 0]], [0], "zero"), ([[np.nan, 0, 0]], [0], "finite")],
)
def test_bad_constraints_are_typed_errors(K, T, match):
    with pytest.raises(ConstraintError, match=match):
        Polytope.from_rows(K, T)
