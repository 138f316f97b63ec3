"""On the adversarial scenario (full deflection at a point 1 m beyond the top face y = 4).

The Done-when pair (human leaves, shared does not) runs the scenario's full 8 s; the rest its first 5 s.
"""
import numpy as np
import pytest

from sharedctl.baselines.mux import HOLD
from sharedctl.baselines.comparison_metrics import summarize

from .conftest import adversarial_run


def test_the_operator_alone_leaves_the_set():
    loop, trace = adversarial_run("human", full=True)
    assert np.count_nonzero(~trace.inside) > 1000          # seconds outside, not a graze
    assert trace.q[:, 1].max() > 4.5                       # through the face y = 4
    assert trace.operator_in_control.all()


@pytest.mark.parametrize("condition", ["ideal", "impaired"])
def test_the_shared_law_keeps_the_robot_inside(condition):
    loop, trace = adversarial_run("shared", condition, full=condition == "ideal")
    assert trace.finite
    assert trace.inside.all()
    assert trace.margin.min() > 0.0
    assert not trace.operator_in_control.all()             # the machine did act


@pytest.mark.parametrize("condition", ["ideal", "impaired"])
def test_the_mux_keeps_the_robot_inside_by_holding_it_at_the_border(condition):
    loop, trace = adversarial_run("mux", condition)
    assert trace.finite
    assert trace.inside.all()
    held = trace.mode == HOLD
    assert held.any() and (~held).any()                    # the hold took over, and handed back
    # while held the operator's force is dropped entirely (priority selection, no blending)
    assert not trace.operator_in_control[held].any()
    assert np.array_equal(trace.u[~held], trace.u_h[~held])


@pytest.mark.parametrize("condition", ["ideal", "impaired"])
def test_the_cbf_filter_keeps_the_robot_inside_its_buffer(condition):
    loop, trace = adversarial_run("cbf", condition)
    assert trace.finite
    assert trace.inside.all()
    # h = −(Kq + T) − δ ≥ 0: the filter keeps δ = 1 cm; sampling may eat a few micrometres of it
    assert trace.margin.min() > 0.01 - 1e-4


def test_metrics_tell_the_strategies_apart_on_the_adversarial_scenario():
    runs = {s: adversarial_run(s, full=s in ("human", "shared")) for s in ("human", "mux", "cbf", "shared")}
    rows = {s: summarize(trace, loop.feasible, 0.002) for s, (loop, trace) in runs.items()}
    assert rows["human"]["violations"] > 0 and rows["human"]["human_authority"] == 1.0
    for s in ("mux", "cbf", "shared"):
        assert rows[s]["violations"] == 0
        assert 0.0 < rows[s]["human_authority"] < 1.0
        assert rows[s]["interventions"] >= 1
        assert rows[s]["tracking_error"] < rows["human"]["tracking_error"]
