"""The shared controller as a sampled step function (what the controller daemon runs)."""
import numpy as np
import pytest

from sharedctl.metrics import summarize
from sharedctl.sampled import simulate_sampled
from sharedctl.shared_controller import NonFiniteCommand, OperatorInput, SharedController
from sharedctl.transform import Desired
from sharedctl.services.scenario_files import load

from .helpers import packaged_run

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
    cont_trace, dt = packaged_run("paper_convex", "ce")           # 20 s at 1 ms
    assert (scenario.duration, dt) == (20.0, 1e-3)
    cont = summarize(cont_trace, dt)
    sampled_trace = simulate_sampled(loop, q0, v0, 20.0, PERIOD)
    samp = summarize(sampled_trace, PERIOD)
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


@pytest.mark.parametrize("name", ["paper_convex", "paper_nonconvex"])
def test_the_reference_reported_under_operator_authority_is_its_own_samples(name):
    """While the operator has authority, StepOutput.q_r (the group the machine would pick) is worked out
    when first read. It must be that of the sample's own (q, q̇), even when the caller has overwritten
    its q and q̇ arrays in place since (as a loop reusing its buffers does). Random states: for most of
    them the pick at the overwritten state would be another group's."""
    loop, q0, _ = load(name).closed_loop("ce")
    controller = SharedController(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference)
    state = controller.initial_state(q0, loop.theta_hat0)
    rng = np.random.default_rng(7)
    low, high = np.array([-3.0, -3.0, -0.5]), np.array([3.0, 3.0, 0.5])
    checked = 0
    for _ in range(200):
        q, v = rng.uniform(low, high), rng.uniform(-1.0, 1.0, 3)
        operator = OperatorInput(Desired(rng.uniform(low, high), np.zeros(3), np.zeros(3)), np.zeros(3), 0.0)
        q_buffer, v_buffer = q.copy(), v.copy()
        _, out = controller.step(state, q_buffer, v_buffer, operator, PERIOD)
        if out.authority.name != "HUMAN":
            continue
        _, fresh = controller.step(state, q.copy(), v.copy(), operator, PERIOD)
        q_buffer[:], v_buffer[:] = rng.uniform(low, high), rng.uniform(-2.0, 2.0, 3)
        np.testing.assert_array_equal(out.q_r, fresh.q_r)
        checked += 1
    assert checked >= 50


def _governed_run(monkeypatch, warm: bool, seconds: float = 4.0):
    """The adversarial wall sampled at 500 Hz with every governor call and root-search probe counted;
    `warm=False` tells every search nothing (the cold search)."""
    import sharedctl.backup as backup_module
    import sharedctl.shared_controller as shared_module

    calls, probes = [], [0]
    real_govern, real_root = shared_module.govern, backup_module._root

    def govern(*args, hint=0.0):
        out = real_govern(*args, hint=hint if warm else 0.0)
        calls.append((hint, out.share))
        return out

    def root(merit, m_lo, m_hi, backup, hint=0.0):
        def counted(lam):
            probes[0] += 1
            return merit(lam)
        return real_root(counted, m_lo, m_hi, backup, hint)

    monkeypatch.setattr(shared_module, "govern", govern)
    monkeypatch.setattr(backup_module, "_root", root)
    loop, q0, v0 = load("adversarial_wall").closed_loop("ce")
    trace = simulate_sampled(loop, q0, v0, seconds, PERIOD)
    return trace, calls, probes[0]


def test_the_sampled_loop_starts_each_governor_search_from_the_last_share(monkeypatch):
    """SharedController keeps the governor's λ in its state and tells the next search (docs/control.md
    §10, the warm start): pressed against the adversarial wall every call is told the λ the call before
    it returned, the run keeps the set, and its searches take at most 60 % of the cold searches' probes."""
    warm, calls, warm_probes = _governed_run(monkeypatch, True)
    monkeypatch.undo()
    cold, cold_calls, cold_probes = _governed_run(monkeypatch, False)
    searched = sum(0.0 < share < 1.0 for _, share in calls)
    assert searched > 100, "the governor hardly searched: the case would test nothing"
    assert calls[0][0] == 0.0 and all(calls[k][0] == calls[k - 1][1] for k in range(1, len(calls)))
    assert sum(0.0 < hint < 1.0 for hint, _ in calls) > 100
    assert warm.inside.all() and cold.inside.all()
    assert warm_probes <= 0.6 * cold_probes, (warm_probes, cold_probes)
