"""time_to_goal of `sharedctl compare` (comparison_metrics.py): the first instant from which the robot
stays within GOAL_TOLERANCE of the projected wish Π(q_d) to the end of the run, or None.

Oracles: instants read off hand-built distance series, and straight-line traces in the box
−1 ≤ x ≤ 1, |y| ≤ 1, |ψ| ≤ 1 whose arrival times are solved by hand.
"""
import numpy as np

from sharedctl.baselines.comparison import ComparisonTrace
from sharedctl.baselines.comparison_metrics import GOAL_TOLERANCE, summarize, time_to_goal
from sharedctl.constraints import FeasibleSet, Polytope

T = np.array([0.0, 0.1, 0.2, 0.3, 0.4])
PERIOD = 0.002


def test_the_goal_is_the_first_instant_of_the_last_stay_within_the_tolerance():
    # inside at 0.1, out again at 0.2, inside from 0.3 to the end
    assert time_to_goal(T, np.array([0.5, 0.05, 0.2, 0.05, 0.08]), 0.1) == 0.3


def test_a_run_that_ends_outside_the_tolerance_has_no_time_to_goal():
    assert time_to_goal(T, np.array([0.5, 0.05, 0.05, 0.05, 0.11]), 0.1) is None


def test_a_run_within_the_tolerance_from_the_start_reaches_the_goal_at_once():
    assert time_to_goal(T, np.full(5, 0.02), 0.1) == 0.0


def test_a_non_finite_distance_counts_as_away():
    assert time_to_goal(T, np.array([0.0, 0.0, np.nan, 0.0, 0.0]), 0.1) == 0.3


def _box() -> FeasibleSet:
    K = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
    return FeasibleSet.from_regions([Polytope.from_rows(K, [-1, -1, -1, -1, -1, -1])])


def _trace(q: np.ndarray, wish: np.ndarray, finite: bool = True) -> ComparisonTrace:
    n = q.shape[0]
    zeros = np.zeros_like(q)
    return ComparisonTrace(t=np.arange(n) * PERIOD, q=q, v=zeros, u=zeros, u_h=zeros, acceleration=zeros, wish=wish,
                           operator_in_control=np.ones(n, bool), hands_off=np.zeros(n, bool), mode=np.zeros(n, int),
                           residual=np.full(n, np.nan), margin=np.ones(n), inside=np.ones(n, bool), finite=finite,
                           commands_sent=0, commands_lost=0)


def test_the_time_to_goal_of_a_robot_driving_at_a_wish_beyond_a_face_is_measured_to_its_projection():
    # wish (3, 0.5, 0) lies beyond the face x = 1: its projection is (1, 0.5, 0). The robot runs along
    # y = 0.5 from x = −1 at 0.5 m/s and stops at x = 0.98: |q − Π(q_d)| = 1 − x ≤ 0.1 from x = 0.9, t = 3.8 s
    t = np.arange(int(round(5.0 / PERIOD))) * PERIOD
    x = np.minimum(-1.0 + 0.5 * t, 0.98)
    q = np.column_stack([x, np.full_like(t, 0.5), np.zeros_like(t)])
    wish = np.tile([3.0, 0.5, 0.0], (t.size, 1))
    row = summarize(_trace(q, wish), _box(), PERIOD)
    assert GOAL_TOLERANCE == 0.1
    assert abs(row["time_to_goal"] - 3.8) <= PERIOD


def test_a_run_cut_short_by_a_non_finite_value_has_no_time_to_goal():
    q = np.zeros((10, 3))
    row = summarize(_trace(q, q.copy(), finite=False), _box(), PERIOD)
    assert row["time_to_goal"] is None
