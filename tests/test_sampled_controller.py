"""The shared controller as a sampled step function (what the controller daemon runs)."""
import numpy as np
import pytest

from sharedctl.metrics import summarize
from sharedctl.sampled import simulate_sampled
from sharedctl.shared_controller import NonFiniteCommand, OperatorInput, SharedController
from sharedctl.simulator import simulate
from sharedctl.transform import Desired
from sharedctl.services.scenario_files import load

PERIOD = 0.002   # 500 Hz, the daemon's loop rate


@pytest.mark.parametrize("controller", ["ce", "nce", "of"])
@pytest.mark.parametrize("name,duration", [("paper_convex", 20.0), ("paper_nonconvex", 16.0)])
def test_paper_scenarios_stay_inside_when_sampled_at_500_hz(name, duration, controller):
    scenario = load(name)
    loop, q0, v0 = scenario.closed_loop(controller)
    trace = simulate_sampled(loop, q0, v0, duration, PERIOD)
    assert trace.finite
    assert trace.inside.all()


def test_sampled_run_matches_the_continuous_simulation():
    """Stated tolerance: final pose within 2 cm, authority share within 5 points, margins within 5 mm."""
    scenario = load("paper_convex")
    loop, q0, v0 = scenario.closed_loop("ce")
    cont = summarize(simulate(loop, q0, v0, 20.0, 1e-3), 1e-3)
    sampled_trace = simulate_sampled(loop, q0, v0, 20.0, PERIOD)
    samp = summarize(sampled_trace, PERIOD)
    cont_trace = simulate(loop, q0, v0, 20.0, 1e-3)
    assert np.linalg.norm(cont_trace.q[-1] - sampled_trace.q[-1]) < 0.02
    assert abs(cont["human_authority"] - samp["human_authority"]) < 0.05
    assert abs(cont["min_margin"] - samp["min_margin"]) < 0.005


def test_a_non_finite_input_never_becomes_a_command():
    scenario = load("paper_convex")
    loop, q0, _ = scenario.closed_loop("ce")
    ctrl = SharedController(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference)
    state = ctrl.initial_state(q0)
    wish = Desired(q0, np.zeros(3), np.zeros(3))
    with pytest.raises(NonFiniteCommand):
        ctrl.step(state, q0, np.zeros(3), OperatorInput(wish, np.array([np.nan, 0.0, 0.0]), 0.0), PERIOD)


def test_step_is_a_pure_function_of_its_state():
    scenario = load("paper_convex")
    loop, q0, _ = scenario.closed_loop("nce")
    ctrl = SharedController(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference)
    state = ctrl.initial_state(q0)
    op = OperatorInput(Desired(q0 + 0.1, np.zeros(3), np.zeros(3)), np.array([1.0, 2.0, 0.0]), 0.3)
    v = np.array([0.1, 0.2, 0.0])
    a_state, a_out = ctrl.step(state, q0, v, op, PERIOD)
    b_state, b_out = ctrl.step(state, q0, v, op, PERIOD)
    assert np.array_equal(a_out.u_s, b_out.u_s)
    assert np.array_equal(a_state.theta_hat, b_state.theta_hat)
