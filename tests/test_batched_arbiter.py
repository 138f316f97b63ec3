"""The batched sharing function's release is the scalar one, robot by robot, the hold of
docs/control.md §6 item 1 included: from random arbiter memories (latched or not, the dwell over or
not, random held rows) and random states, wishes and pushes on seeded random sets, StepKernel.decide
latches, blends and remembers the held rows exactly as sharing.arbitrate does for each robot. The
batch keeps held rows by the group table's distinct rows, the scalar arbiter by FeasibleSet.row_ids:
the two numberings are one. Without a backup model, so that both classify the same rows.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

from sharedctl.batched import BatchProblem
from sharedctl.batched.arbiter import ArbiterArrays
from sharedctl.batched.operators import DesiredBatch
from sharedctl.batched.sampled import SampledBatch
from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.scenario import parse
from sharedctl.services.studies.montecarlo.cases import random_regions, scenario_data
from sharedctl.sharing import ArbiterState, LawRole, arbitrate, operator_pushes, push_turned_away
from sharedctl.transform import Desired

pytestmark = pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning",
                                        "ignore:divide by zero encountered:RuntimeWarning")

N = 600
DT = 0.002


def _case(kind: str, seed: int):
    rng = np.random.default_rng(seed)
    regions = random_regions(rng, kind)
    feasible = FeasibleSet.from_regions([Polytope.from_rows(K, T) for K, T in regions])
    K, T = feasible.row_matrix, np.concatenate([r.T for r in feasible.regions])
    q = np.vstack([rng.uniform(-3.0, 3.0, (2, N)), rng.uniform(-1.7, 1.7, (1, N))])
    near = rng.integers(0, K.shape[0], N)
    for i in range(0, N, 2):        # every other robot within −0.8…0.02 of a random face
        k = K[near[i]]
        q[:, i] += (rng.uniform(-0.8, 0.02) - (float(k @ q[:, i]) + T[near[i]])) * k / float(k @ k)
    v = rng.uniform(-2.0, 2.0, (3, N))
    wish = q + rng.uniform(-1.5, 1.5, (3, N))
    u_h = rng.uniform(-40.0, 40.0, (3, N))
    start = next(q[:, i] for i in range(N) if feasible.contains(q[:, i]))
    data = scenario_data(regions, start, start, 30.0, "ce")
    data["backup"] = {"enabled": False}
    loop = parse(data).closed_loop("ce")[0]
    return rng, feasible, loop, q, v, wish, u_h


@pytest.mark.parametrize("kind,seed", [("convex", 1), ("convex", 2), ("union", 3), ("union", 4), ("union", 5)])
def test_the_batched_release_and_held_rows_are_the_scalar_ones(kind, seed):
    rng, feasible, loop, q, v, wish, u_h = _case(kind, seed)
    batch = SampledBatch(BatchProblem.replicate(loop, q.T, np.zeros((N, 3))), DT)
    table = batch.engine.table
    assert [tuple(r.tolist()) for r in table.region_rows] == [
        feasible.row_ids[a:b] for a, b in feasible.row_spans]        # one numbering of the distinct rows
    P = table.row_K.shape[0]
    memory = ArbiterArrays(rng.random(N) < 0.7, np.full(N, -1), np.zeros(N, dtype=np.int64),
                           rng.choice([0.0, 0.4, 1.0], N), rng.choice([0.1, 0.3, 1.0], N),
                           np.zeros(N, np.int64), np.zeros(N, np.int64), rng.random((N, P)) < 0.3)
    memory.held &= memory.latched[:, None]
    fleet = copy.deepcopy(batch.fleet)
    fleet.arbiter = copy.deepcopy(memory)
    intent = np.ones(N)
    batch.kernel.decide(fleet, q, v, DesiredBatch(wish, np.zeros((3, N)), np.zeros((3, N))), u_h, intent, DT)
    after = fleet.arbiter
    held_changed = kept_by_hold = 0
    params, eps, bands = loop.sharing, loop.reference.epsilon, loop.sharing.bands
    zero = np.zeros(3)
    for i in range(N):
        state = ArbiterState(bool(memory.latched[i]), None, LawRole.TRACKING, float(memory.k_h[i]),
                             float(memory.machine_time[i]), 0, 0, tuple(np.flatnonzero(memory.held[i]).tolist()))
        pushes = operator_pushes(feasible, u_h[:, i])
        rows = feasible.row_values(q[:, i], v[:, i])
        away = push_turned_away(feasible, q[:, i].tolist(), Desired(wish[:, i], zero, zero).q, u_h[:, i], eps, bands,
                                rows[0], pushes)
        new, _ = arbitrate(feasible, params, state, q[:, i], v[:, i], 1.0, DT, lambda g: 0.0, None, rows, away,
                           pushes, float(v[:, i] @ u_h[:, i]))
        assert bool(after.latched[i]) == new.machine_latched, i
        assert float(after.k_h[i]) == new.k_h, i
        assert tuple(np.flatnonzero(after.held[i]).tolist()) == new.held_rows, i
        literal, _ = arbitrate(feasible, params.__class__(params.bands, params.blend_time_constant, params.mode,
                                                          params.min_machine_dwell, False),
                               state, q[:, i], v[:, i], 1.0, DT, lambda g: 0.0, None, rows, away, pushes,
                               float(v[:, i] @ u_h[:, i]))
        kept_by_hold += new.machine_latched and not literal.machine_latched
        held_changed += new.held_rows != state.held_rows
    assert kept_by_hold > 10 and held_changed > 10, (kept_by_hold, held_changed)    # not vacuous
