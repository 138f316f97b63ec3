"""The Monte-Carlo's 95 % upper bound on a violation probability (services/studies/montecarlo/bound.py) is
the exact Clopper–Pearson one: checked against the binomial tail itself, summed here term by term with
math.comb and solved for p by bisection — no Beta function, no scipy."""
from __future__ import annotations

import math

import pytest

from sharedctl.services.studies.montecarlo.bound import upper_95

ALPHA = 0.05


def binomial_cdf(k: int, n: int, p: float) -> float:
    """P(Binomial(n, p) ≤ k), the exact sum (each term's powers in log space, so large n does not underflow)."""
    if p <= 0.0:
        return 1.0
    if p >= 1.0:
        return 1.0 if k >= n else 0.0
    log_p, log_q = math.log(p), math.log1p(-p)
    return sum(math.comb(n, i) * math.exp(i * log_p + (n - i) * log_q) for i in range(k + 1))


def tail_solution(k: int, n: int) -> float:
    """The p in (0, 1) at which P(Binomial(n, p) ≤ k) = α (the tail falls as p grows), by bisection."""
    low, high = 0.0, 1.0
    for _ in range(200):
        mid = (low + high) / 2
        if binomial_cdf(k, n, mid) > ALPHA:
            low = mid
        else:
            high = mid
    return (low + high) / 2


@pytest.mark.parametrize("k,n", [(0, 1), (0, 10), (1, 10), (5, 10), (9, 10), (0, 100), (3, 100), (20, 50),
                                 (0, 3000), (0, 100_000), (3, 100_000)])
def test_the_bound_is_where_k_or_fewer_events_become_a_five_percent_tail(k, n):
    assert upper_95(k, n) == pytest.approx(tail_solution(k, n), rel=1e-9)


@pytest.mark.parametrize("n", [1, 2, 10, 1000, 100_000])
def test_with_no_event_the_bound_is_one_minus_the_nth_root_of_alpha(n):
    assert upper_95(0, n) == pytest.approx(1 - ALPHA ** (1 / n), rel=1e-9)


@pytest.mark.parametrize("n", [1, 7, 1000])
def test_with_every_trial_an_event_nothing_bounds_the_probability_below_one(n):
    assert upper_95(n, n) == 1.0


@pytest.mark.parametrize("n", [10_000, 100_000, 1_000_000])
def test_no_event_in_n_runs_bounds_the_probability_by_three_over_n(n):
    """The rule of three: −ln(0.05) ≈ 2.996."""
    assert upper_95(0, n) * n == pytest.approx(3.0, abs=0.01)


def test_each_further_event_raises_the_bound():
    bounds = [upper_95(k, 1000) for k in range(6)]
    assert bounds == sorted(bounds) and len(set(bounds)) == len(bounds)


@pytest.mark.parametrize("k,n", [(0, 0), (0, -1), (-1, 10), (11, 10)])
def test_a_count_outside_zero_to_n_or_no_trial_is_refused(k, n):
    with pytest.raises(ValueError):
        upper_95(k, n)
