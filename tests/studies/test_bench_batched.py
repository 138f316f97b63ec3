"""The batched-simulator benchmark's workload (services/bench/batched.py); timing is not asserted."""
import numpy as np

from sharedctl.batched import simulate_batch
from sharedctl.services.studies.bench.batched import DT, _loop, fleet, polygon_loop


def test_the_benchmark_fleet_starts_inside_and_the_machine_takes_over():
    loop = _loop()
    problem = fleet(loop, 64, seed=3)
    assert all(loop.feasible.contains(problem.q0[:, i]) for i in range(problem.size))
    result = simulate_batch(problem, 0.2, DT)
    assert result.violations.sum() == 0 and result.finite.all()
    assert (result.switches > 0).sum() >= 16, "the workload must exercise the machine laws, not only the operator"


def test_polygon_sets_have_the_group_counts_the_scaling_table_reports():
    counts = [len(polygon_loop(sides).feasible.groups) for sides in (4, 6, 8, 12)]
    assert counts == [8, 24, 48, 120]
    assert np.all(np.isfinite(polygon_loop(6).feasible.stack.K_inv))
