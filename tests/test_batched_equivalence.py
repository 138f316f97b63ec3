"""The batched simulator (sharedctl.batched) reproduces simulator.simulate robot by robot.

Stated tolerance (docs/performance.md, "Batched simulator"): for every robot, the same number of samples;
|Δq|, |Δq̇|, |Δq̇̂|, |Δθ̂| ≤ 1e-9 and |Δu| ≤ 1e-6 N at every sample; authority, group, law role
and set class identical at every sample; the same authority and group switch counts; the
summary (metrics.summarize) equal to the same tolerances. Durations are short (0.5–1 s at 2 ms).
"""
import dataclasses
import tomllib
from importlib import resources

import numpy as np
import pytest

from sharedctl.batched import BatchProblem, operators_from_models, simulate_batch
from sharedctl.human import AdversarialOperator, LineTrajectory, ScriptedOperator
from sharedctl.metrics import summarize
from sharedctl.scenario import parse
from sharedctl.simulator import ClosedLoop, simulate

DT = 0.002
DURATION = 0.6
STATE_TOL = 1e-9      # m, m/s, rad, rad/s and θ̂ units
FORCE_TOL = 1e-6      # N (N·m for the yaw row)

#: initial states (most near faces, moving towards them) with at least one take-over per scenario within 0.6 s
STARTS = {
    "paper_convex": [([-0.5, 3.8, 0.0], [0.0, 0.6, 0.0]), ([-0.75, 2.0, 0.3], [-0.7, 0.1, 0.4]),
                     ([-0.9, 3.7, -0.2], [-0.4, 0.5, -0.3])],
    "paper_nonconvex": [([-0.25, 1.0, 0.0], [0.6, 0.0, 0.0]), ([-0.2, 0.2, 0.1], [0.5, 0.3, 0.0]),
                        ([0.5, -0.3, 0.0], [0.0, 0.7, 0.2])],
    "adversarial_wall": [([0.0, 3.8, 0.0], [0.0, 0.5, 0.0]), ([0.5, 3.7, 0.2], [0.2, 0.6, 0.0]),
                         ([-0.6, 3.6, 0.0], [0.0, 0.0, 0.0])],
}


def _scenario(name, **sharing):
    data = tomllib.loads(resources.files("sharedctl").joinpath(f"scenarios/{name}.toml").read_text())
    if sharing:
        data["sharing"] = {**data.get("sharing", {}), **sharing}
    return parse(data)


def _assert_same(loops, q0, v0, duration=DURATION):
    batch = simulate_batch(BatchProblem.from_loops(loops, q0, v0), duration, DT, record=True)
    for i, loop in enumerate(loops):
        ref = simulate(loop, q0[i], v0[i], duration, DT)
        got = batch.trace(i, loop.model)
        assert got.t.size == ref.t.size, f"robot {i}: {got.t.size} samples, scalar {ref.t.size}"
        for name in ("q", "v", "v_hat", "theta_hat"):
            np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=0, atol=STATE_TOL,
                                       err_msg=f"robot {i} {name}")
        for name in ("u_h", "u_f", "u_s", "tau"):
            np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=0, atol=FORCE_TOL,
                                       err_msg=f"robot {i} {name}")
        for name in ("authority", "group", "role", "set_class", "inside", "true_class", "own_law"):
            np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=f"robot {i} {name}")
        assert (got.switches, got.group_switches, got.finite) == (ref.switches, ref.group_switches, ref.finite)
        expected = summarize(ref, DT)
        _assert_same_summary(batch.summary(i), expected)
        _assert_same_summary(summarize(got, DT), expected)
    return batch


def _assert_same_summary(got: dict, expected: dict):
    assert got.keys() == expected.keys()
    for key, value in expected.items():
        if value is None or isinstance(value, (bool, int)):
            assert got[key] == value, key
        else:
            np.testing.assert_allclose(got[key], value, rtol=0, atol=STATE_TOL, err_msg=key)


@pytest.mark.parametrize("controller", ["ce", "nce", "of"])
@pytest.mark.parametrize("name", ["paper_convex", "paper_nonconvex", "adversarial_wall"])
def test_batch_equals_scalar_runs_in_shared_mode(name, controller):
    loop, _, _ = _scenario(name).closed_loop(controller)
    q0, v0 = (np.array([s[k] for s in STARTS[name]], float) for k in (0, 1))
    batch = _assert_same([loop] * len(q0), q0, v0)
    assert batch.switches.sum() > 0, "the machine never took over: the case would test nothing"


@pytest.mark.parametrize("controller", ["nce", "of"])
def test_batch_equals_scalar_runs_with_the_tracking_laws_engaged(controller):
    """Machine-only mode: (13) with its filters and (25) with the observer run from t = 0."""
    loop, q0, _ = _scenario("paper_convex", mode="machine").closed_loop(controller)
    starts = np.array([q0, [-0.5, 3.5, 0.0], [-0.75, 2.0, 0.3]])
    speeds = np.array([[0.0, 0.0, 0.0], [0.0, 0.9, 0.0], [-0.7, 0.1, 0.4]])
    _assert_same([loop] * 3, starts, speeds, duration=0.6)


@pytest.mark.parametrize("backup", [True, False], ids=["backup", "no_backup"])
def test_robots_may_differ_in_operator_and_estimate(backup):
    """The scenario's operator, a scripted one with other gains and wish, an adversary, and three θ̂(0), in one batch;
    with the scenario's backup model (the governor on) and without one."""
    base, q0, _ = _scenario("paper_convex").closed_loop("ce")
    kp = np.full(3, 20.0)
    humans = [
        base.human,
        ScriptedOperator(LineTrajectory(np.array([-0.9, 1.0, 0.0]), np.array([0.0, 0.9, 0.2])), kp * 2.0,
                         np.full(3, 5.0)),
        AdversarialOperator(LineTrajectory(np.array([-2.0, 2.0, 0.0]), np.zeros(3)), kp, np.array([-2.0, 2.0, 0.0]),
                            0.5),
    ]
    loops = [ClosedLoop(base.model, base.feasible, h, base.controller, base.sharing, base.reference, th,
                        base.backup if backup else None)
             for h, th in zip(humans, ([0.0, 0.0, 0.0], [10.0, 1.0, 5.0], [20.0, 2.0, 8.0]))]
    starts = np.array([[-0.5, 3.5, 0.0], [-0.5, 3.0, 0.0], [-0.6, 2.0, 0.0]])
    _assert_same(loops, starts, np.zeros((3, 3)))


def test_an_escape_is_recorded_as_the_scalar_simulator_records_it():
    """Output feedback at 40 m/s towards a face: an RK stage leaves the group; the run stops with a violation."""
    loop, _, _ = _scenario("paper_convex").closed_loop("of")
    q0 = np.array([[-0.5, 3.6, 0.0], [-0.5, 3.0, 0.0]])
    v0 = np.array([[0.0, 40.0, 0.0], [0.0, 0.5, 0.0]])
    batch = _assert_same([loop] * 2, q0, v0, duration=0.5)
    assert batch.violations[0] == 1 and not batch.finite[0]
    assert batch.steps[1] == round(0.5 / DT) and batch.violations[1] == 0


def test_random_batch_stays_inside():
    """Invariance over 1000 random robots (state, operator gain, target and deflection) against the adversarial
    wall for 1 s."""
    loop, _, _ = _scenario("adversarial_wall").closed_loop("ce")
    rng = np.random.default_rng(7)
    N = 1000
    q0 = np.column_stack([rng.uniform(-0.8, 0.8, N), rng.uniform(0.8, 3.7, N), rng.uniform(-1.0, 1.0, N)])
    v0 = rng.uniform(-0.8, 0.8, (N, 3))
    targets = np.column_stack([rng.uniform(-2.0, 2.0, N), rng.uniform(4.2, 6.0, N), rng.uniform(-2.0, 2.0, N)])
    humans = [AdversarialOperator(LineTrajectory(t, np.zeros(3)), np.full(3, rng.uniform(10.0, 40.0)), t,
                                  rng.uniform(0.3, 1.5))
              for t in targets]
    problem = BatchProblem.replicate(loop, q0, v0, operators_from_models(humans, 3))
    result = simulate_batch(problem, 1.0, DT)
    assert result.finite.all()
    assert result.violations.sum() == 0
    assert np.nanmin(result.min_margin) > 0.0
    assert (result.human_authority < 1.0).sum() > N // 4, "most robots should meet the wall within 1 s"
    # the same robots, one by one, agree with the batch (a sample of them)
    for i in rng.choice(N, 3, replace=False):
        one = dataclasses.replace(loop, human=humans[i])      # the scenario's loop (its backup model too)
        expected = summarize(simulate(one, q0[i], v0[i], 1.0, DT), DT)
        _assert_same_summary(result.summary(i), expected)
