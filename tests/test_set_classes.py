"""The class of every constraint group at once (sharedctl.sets.classify_groups) is classify_rows on
each group's rows x = K_g q + T_g, ẋ = K_g v, for the paper's convex and non-convex feasible sets:
inside and outside the set, with a row placed within the bands b0, b1, b2 of its face and its rate
on or next to an allowance curve f_b1, f_b2; and, given the row values directly, with rows exactly
on the band edges and rates exactly on the curves, infinite or NaN."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sharedctl.services.scenario_files import load
from sharedctl.sets import allowance, classify_groups, classify_rows

PAPER_SETS = ("paper_convex", "paper_nonconvex")
_LOOPS: dict = {}


def paper_loop(name):
    """The paper scenario's closed loop (its feasible set and sharing bands), built once per name."""
    if name not in _LOOPS:
        _LOOPS[name] = load(name).closed_loop("ce")[0]
    return _LOOPS[name]


def per_group_classify_rows(feasible, q, v, bands):
    return tuple(classify_rows(g.values(q), g.K @ v, bands) for g in feasible.groups)


coordinates = st.floats(-6.0, 6.0)      # around every face of the paper's sets, inside and outside them
rates = st.floats(-3.0, 3.0)
non_finite = st.sampled_from([math.inf, -math.inf, math.nan])


@st.composite
def states(draw, feasible, bands):
    """(q, v): anywhere in a box around the set, or with one row x_j within the bands of its face
    (exactly on −b0, −b1, −b2, the face, or between) and, sometimes, ẋ_j on or next to f_b1 or f_b2."""
    n = feasible.n
    K = np.vstack([r.K for r in feasible.regions])
    T = np.concatenate([r.T for r in feasible.regions])
    q = np.array(draw(st.lists(coordinates, min_size=n, max_size=n)))
    v = np.array(draw(st.lists(rates, min_size=n, max_size=n)))
    if draw(st.booleans()):
        j = draw(st.integers(0, len(T) - 1))
        edges = [0.0, -bands.b0, -bands.b1, -bands.b2]
        x = draw(st.one_of(st.sampled_from(edges), st.floats(-bands.b2 - 0.05, 0.05)))
        q = q + (x - (K[j] @ q + T[j])) * K[j]          # rows have unit length
        if draw(st.booleans()):
            b = draw(st.sampled_from([bands.b1, bands.b2]))
            curve = float(allowance(np.array([K[j] @ q + T[j]]), b)[0])
            if math.isfinite(curve):
                rate = draw(st.sampled_from([curve, math.nextafter(curve, math.inf), math.nextafter(curve, -math.inf)]))
                v = v + (rate - K[j] @ v) * K[j]
    return q, v


@pytest.mark.parametrize("name", PAPER_SETS)
@settings(max_examples=400, deadline=None)
@given(data=st.data())
def test_classify_groups_is_classify_rows_for_every_group(name, data):
    loop = paper_loop(name)
    feasible, bands = loop.feasible, loop.sharing.bands
    q, v = data.draw(states(feasible, bands))
    assert classify_groups(feasible, q, v, bands) == per_group_classify_rows(feasible, q, v, bands)


def _neighbours(value):
    return [value, math.nextafter(value, math.inf), math.nextafter(value, -math.inf)]


@st.composite
def row_values(draw, feasible, bands):
    """Every stacked row's x (on a band edge −b0, −b1, −b2 or the face, a float next to one, or
    anywhere) and ẋ (on f_b1(x) or f_b2(x), next to it, ±0, ±∞, NaN or anywhere), as
    `feasible.row_values` gives them."""
    edges = (0.0, -bands.b0, -bands.b1, -bands.b2)
    next_to_edges = [x for edge in edges for x in _neighbours(edge)[1:]]
    values, row_rates = [], []
    for _ in range(sum(r.K.shape[0] for r in feasible.regions)):
        x = draw(st.one_of(st.sampled_from(edges), st.sampled_from(next_to_edges), st.floats(-1.0, 0.2), non_finite))
        curves = [float(allowance(np.array([x]), b)[0]) for b in (bands.b1, bands.b2)]
        on_curves = [r for c in curves if math.isfinite(c) for r in _neighbours(c)] or [0.0]
        values.append(x)
        row_rates.append(draw(st.one_of(st.sampled_from(on_curves), st.sampled_from([0.0, -0.0]), non_finite, rates)))
    return values, row_rates


@pytest.mark.parametrize("name", PAPER_SETS)
@settings(max_examples=400, deadline=None)
@given(data=st.data())
def test_classify_groups_is_classify_rows_on_rows_exactly_on_the_band_edges(name, data):
    loop = paper_loop(name)
    feasible, bands = loop.feasible, loop.sharing.bands
    rows = data.draw(row_values(feasible, bands))
    expected = tuple(classify_rows(*map(np.array, feasible.group_rows(g, rows)), bands)
                     for g in range(len(feasible.groups)))
    assert classify_groups(feasible, None, None, bands, rows) == expected


@pytest.mark.parametrize("name", PAPER_SETS)
def test_classify_groups_takes_row_values_the_caller_has_already(name):
    loop = paper_loop(name)
    feasible, bands = loop.feasible, loop.sharing.bands
    q, v = np.array([-0.9, 3.97, 0.0]), np.array([0.0, 0.5, 0.0])
    rows = feasible.row_values(q, v)
    assert classify_groups(feasible, q, v, bands, rows) == classify_groups(feasible, q, v, bands)
    assert classify_groups(feasible, q, v, bands) == per_group_classify_rows(feasible, q, v, bands)


@pytest.mark.parametrize("name", PAPER_SETS)
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("where", ["q", "v"])
def test_classify_groups_is_classify_rows_on_non_finite_states_too(name, bad, where):
    loop = paper_loop(name)
    feasible, bands = loop.feasible, loop.sharing.bands
    q, v = np.array([-0.9, 3.97, 0.0]), np.array([0.0, 0.5, 0.0])
    (q if where == "q" else v)[1] = bad
    with np.errstate(invalid="ignore"):
        expected = per_group_classify_rows(feasible, q, v, bands)
    assert classify_groups(feasible, q, v, bands) == expected
