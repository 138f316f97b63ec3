"""The sampled batch's sharing function with every group's part on demand equals the eager one.

`GroupsOnDemand` (sharedctl/batched/geometry.py) computes every group's p and selection value only for
the robots that ask; the arbiter asks (sharedctl/batched/arbiter.py, `chosen` a function) only for the
robots whose group it chooses anew. On seeded random sets (convex polygons, unions of two boxes, the
packaged scenarios') and states inside, near the faces and outside, with random arbiter memories in
both sharing modes: the rows, the asked-for p and values, and every decision and arbiter field of
StepKernel.decide are exactly the eager code's, and the group is asked for exactly the robots the
arbiter chooses anew.
"""
from __future__ import annotations

import copy
import tomllib
from dataclasses import fields
from importlib import resources

import numpy as np
import pytest

from sharedctl.batched import BatchProblem, step
from sharedctl.batched.arbiter import ArbiterArrays
from sharedctl.batched.geometry import GroupsOnDemand, GroupTable, all_groups, missed_rows, row_reference
from sharedctl.batched.operators import DesiredBatch
from sharedctl.batched.sampled import SampledBatch
from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.reference import ReferenceShape
from sharedctl.scenario import parse
from sharedctl.services.studies.montecarlo.cases import random_regions, scenario_data

pytestmark = pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning",
                                        "ignore:divide by zero encountered:RuntimeWarning")

N = 2000
DT = 0.002
SHAPE = ReferenceShape()


def _packaged(name):
    data = tomllib.loads(resources.files("sharedctl").joinpath(f"scenarios/{name}.toml").read_text())
    return parse(data).closed_loop("ce")[0].feasible


def _sets():
    rng = np.random.default_rng(23)
    out = [(f"{kind}-{i}", FeasibleSet.from_regions([Polytope.from_rows(K, T) for K, T in random_regions(rng, kind)]))
           for kind in ("convex", "union") for i in range(2)]
    return out + [(name, _packaged(name)) for name in ("paper_convex", "paper_nonconvex")]


SETS = _sets()


def _states(rng, feasible):
    """q over a box around the set, a third moved to within −0.7…0.05 of a random face; v, wishes."""
    K, T = feasible.row_matrix, np.concatenate([r.T for r in feasible.regions])
    q = np.vstack([rng.uniform(-3.0, 3.0, (2, N)), rng.uniform(-1.0, 1.0, (1, N))])
    rows = rng.integers(0, K.shape[0], N)
    for i in np.flatnonzero(rng.random(N) < 0.35):
        k = K[rows[i]]
        q[:, i] += (rng.uniform(-0.7, 0.05) - (float(k @ q[:, i]) + T[rows[i]])) * k / float(k @ k)
    v = rng.uniform(-2.0, 2.0, (3, N))
    return q, v, q + rng.uniform(-1.0, 1.0, (3, N)), rng.uniform(-1.0, 1.0, (3, N))


def _memory(rng, table):
    """A random arbiter memory: latched or not, an old group (or none), either law role."""
    G = table.groups
    return ArbiterArrays(rng.random(N) < 0.5, rng.integers(-1, G, N), rng.integers(0, 2, N),
                         rng.choice([0.0, 0.4, 1.0], N), rng.uniform(0.0, 0.6, N), np.zeros(N, np.int64),
                         np.zeros(N, np.int64), rng.random((N, table.row_K.shape[0])) < 0.3)


@pytest.mark.parametrize("name,feasible", SETS, ids=[s[0] for s in SETS])
def test_every_groups_part_on_demand_is_the_eager_one(name, feasible):
    rng = np.random.default_rng(abs(hash(name)) % 2**32)
    table = GroupTable.of(feasible)
    q, v, wish, wish_dot = _states(rng, feasible)
    ref = row_reference(table, wish, wish_dot, SHAPE)
    eager, lazy = all_groups(table, q, v, ref, 1.0), GroupsOnDemand(table, q, v, ref, 1.0)
    for field in ("x", "x_dot", "z", "shifted_reference"):
        assert np.array_equal(getattr(eager.rows, field), getattr(lazy.rows, field), equal_nan=True), field
    cols = np.sort(rng.choice(N, 300, replace=False))
    p, value = lazy.values(cols)
    assert np.array_equal(p, eager.p[:, :, cols], equal_nan=True)
    assert np.array_equal(value, eager.value[:, cols], equal_nan=True)
    finite = np.isfinite(value)
    assert finite.any() and (~finite).any()
    group = rng.integers(0, table.groups, cols.size)
    assert np.array_equal(lazy.p_of(group, cols), eager.p_of(group, cols), equal_nan=True)
    assert lazy.p_of(group, cols).shape == (3, cols.size)


@pytest.mark.parametrize("mode", ["shared", "machine"])
@pytest.mark.parametrize("name,feasible", SETS, ids=[s[0] for s in SETS])
def test_the_sampled_sharing_function_on_demand_decides_as_the_eager_one(name, feasible, mode, monkeypatch):
    """StepKernel.decide with and without `on_demand`, from the same arbiter memory: the same decisions
    and memory, and the group function asked for exactly the robots held after the sample whose old
    group is none, newly latched, no longer containing q or missing a hazardous row."""
    rng = np.random.default_rng(abs(hash(name)) % 2**32 + 1)
    q, v, wish_q, wish_dot = _states(rng, feasible)
    regions = [(r.K, r.T) for r in feasible.regions]
    start = next(q[:, i] for i in range(N) if feasible.contains(q[:, i]))
    data = scenario_data(regions, start, start, 30.0, "nce")
    data["sharing"] = {"mode": mode}
    loop = parse(data).closed_loop("nce")[0]
    batch = SampledBatch(BatchProblem.replicate(loop, q.T, np.zeros((N, 3))), DT)
    table = batch.engine.table
    memory = _memory(rng, table)
    fleets = []
    for _ in range(2):
        fleet = copy.deepcopy(batch.fleet)
        fleet.arbiter = ArbiterArrays(*(getattr(memory, f.name).copy() for f in fields(memory)))
        fleets.append(fleet)
    wish = DesiredBatch(wish_q, wish_dot, np.zeros((3, N)))
    u_h, intent = rng.uniform(-30.0, 30.0, (3, N)), rng.uniform(0.0, 1.0, N)
    asked = []
    arbitrate = step.arbitrate

    def spy(table, params, state, situation, row_x, missed, chosen, *args):
        if callable(chosen):
            inner = chosen

            def chosen(want):
                asked.append(want.copy())
                return inner(want)
        return arbitrate(table, params, state, situation, row_x, missed, chosen, *args)

    monkeypatch.setattr(step, "arbitrate", spy)
    eager = batch.kernel.decide(fleets[0], q, v, wish, u_h, intent, DT)
    lazy = batch.kernel.decide(fleets[1], q, v, wish, u_h, intent, DT, on_demand=True)
    assert lazy[2] is None and eager[2] is not None
    for f in fields(eager[3]):
        assert np.array_equal(getattr(eager[3], f.name), getattr(lazy[3], f.name)), f.name
    for f in fields(memory):
        assert np.array_equal(getattr(fleets[0].arbiter, f.name), getattr(fleets[1].arbiter, f.name)), f.name
    (want,) = asked
    situation, after = eager[1], fleets[1].arbiter
    old = np.maximum(memory.group, 0)
    cols = np.arange(N)
    stale = ((memory.group < 0) | (after.latched & ~memory.latched) | ~situation.containing[table.region_of[old], cols]
             | (missed_rows(table, situation)[old, cols] > 0))
    needs = np.ones(N, bool) if mode == "machine" else after.latched
    assert np.array_equal(want, needs & stale)
    assert 0 < want.sum() < N
    chosen = eager[2]
    assert np.array_equal(after.group, np.where(want & (chosen >= 0), chosen, memory.group))
