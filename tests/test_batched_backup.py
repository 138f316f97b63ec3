"""The batched fail-safe stop (sharedctl/batched/backup.py) equals sharedctl/backup.py robot by robot.

The oracle is the scalar module, one state at a time, on seeded random states of the packaged
scenarios' feasible sets (convex, and the non-convex union of two polytopes): states inside and
outside Q_a, blocks at rest, speeds on both branches of the braking distance, commands that are
already backup-safe, that need the search for λ and that not even the fallback can save; for the
robot's model (a hold deviation per block, shared brakes) also with a slack on the velocity (output
feedback: each robot its own). Values
agree to rounding (REACH_TOL, FORCE_TOL, and λ: the regula falsi's chords are built from margins
that may differ in the last bit); decisions — which robots the governor moves, which rows move —
are identical. The omni robot's governor and speed-aware rows run twice: in numpy and compiled
(sharedctl/batched/compiled_backup.py, where numba is installed).
"""
from __future__ import annotations

import dataclasses
import tomllib
from importlib import resources

import numpy as np
import pytest

from sharedctl.backup import BackupModel, BrakeBlock, govern, speed_aware_rows
from sharedctl.batched import BatchProblem
from sharedctl.batched import compiled_backup
from sharedctl.batched.backup import BackupTable
from sharedctl.batched.geometry import GroupTable
from sharedctl.models import OmniRobot
from sharedctl.models.omni_robot import OmniRobotParameters
from sharedctl.scenario import parse

DT = 0.002
REACH_TOL = 1e-12     # m (reaches, margins, row values) and m/s² (accelerations)
FORCE_TOL = 1e-9      # N, N·m

#: stops other than the omni robot's: Coulomb-only translation braking in any direction, with and without a hold
PLAIN = BackupModel(0.05, (BrakeBlock((0, 1), 2.0, 0.0), BrakeBlock((2,), 3.0, 0.5, 0.0, 1e-3)), 0.02)
OTHER = {"plain": PLAIN, "no_hold": dataclasses.replace(PLAIN, hold=0.0)}


def _loop(name):
    data = tomllib.loads(resources.files("sharedctl").joinpath(f"scenarios/{name}.toml").read_text())
    loop, _, _ = parse(data).closed_loop("ce")
    return loop


def _case(name, which, kernel="numpy"):
    """(loop, backup model, its batched table, the distinct row of each stacked row of the scalar code);
    `kernel`: the table's governor and speed-aware rows in numpy or compiled."""
    loop = _loop(name)
    backup = loop.backup if which == "omni" else OTHER[which]
    table = GroupTable.of(loop.feasible)
    stacked = np.concatenate(table.region_rows)
    assert np.array_equal(table.row_K[stacked], loop.feasible.row_matrix)
    batch = BackupTable.of(backup, loop.feasible, table, compiled=kernel == "compiled")
    assert (batch.compiled is not None) == (kernel == "compiled")
    return loop, backup, batch, stacked


NUMBA = pytest.mark.skipif(not compiled_backup.available(), reason="numba is not installed (the montecarlo extra)")


def _kernels(cases):
    """Each case in numpy, and the omni robot's compiled too."""
    out = [pytest.param(*case, "numpy", id=f"{case[0]}-{case[1]}-numpy") for case in cases]
    return out + [pytest.param(*case, "compiled", marks=NUMBA, id=f"{case[0]}-{case[1]}-compiled")
                  for case in cases if case[1] == "omni"]


def _hints(rng, shares):
    """Each robot's last λ for the governor's warm start (backup._root): its λ now, a few grid steps
    from it, anywhere in [0, 1], or none."""
    N = shares.size
    kind = rng.integers(0, 4, N)
    near = np.clip(shares + rng.integers(-3, 4, N) * 2.0 ** -12, 0.0, 1.0)
    return np.select([kind == 0, kind == 1, kind == 2], [shares, near, rng.uniform(0.0, 1.0, N)], 0.0)


def _states(rng, N):
    """(q, v, w) (N, 3): positions around and outside the sets, velocities and a second vector (an
    acceleration, in m/s²) whose translation and yaw blocks are at rest, crawling (below the braking
    distance's quadratic branch's threshold) or moving."""
    q = np.column_stack([rng.uniform(-1.5, 1.5, N), rng.uniform(-0.5, 4.5, N), rng.uniform(-1.8, 1.8, N)])

    def vectors(scale_moving):
        x = rng.uniform(-1.0, 1.0, (N, 3))
        scale = rng.choice([0.0, 1e-7, 0.3, scale_moving], size=(N, 2), p=[0.15, 0.15, 0.35, 0.35])
        x[:, :2] *= scale[:, :1]
        x[:, 2:] *= scale[:, 1:]
        return x

    return q, vectors(2.5), vectors(8.0)


GOVERNED = [("paper_convex", "omni"), ("paper_nonconvex", "omni"), ("paper_nonconvex", "plain")]
CASES = GOVERNED + [("paper_convex", "no_hold")]      # without a hold the command barely matters: no bisection


@pytest.mark.parametrize("name,which", CASES)
def test_state_and_command_reaches_equal_the_scalar_reaches(name, which):
    loop, backup, batch, stacked = _case(name, which)
    _, v, a = _states(np.random.default_rng(11), 300)
    state = batch.state_reach(v.T)[stacked]
    command = batch.command_reach(v.T, a.T)[stacked]
    K = loop.feasible.row_matrix
    for i in range(v.shape[0]):
        np.testing.assert_allclose(state[:, i], backup.state_reach(K, v[i]), rtol=0, atol=REACH_TOL)
        np.testing.assert_allclose(command[:, i], backup.command_reach(K, v[i], a[i]), rtol=0, atol=REACH_TOL)


@pytest.mark.parametrize("name,which", CASES)
def test_state_and_command_margins_equal_the_scalar_margins(name, which):
    loop, backup, batch, _ = _case(name, which)
    q, v, a = _states(np.random.default_rng(12), 300)
    state = batch.state_margin(q.T, v.T)
    command = batch.command_margin(q.T, v.T, a.T)
    expected_state = [backup.state_margin(loop.feasible, q[i], v[i]) for i in range(q.shape[0])]
    expected_command = [backup.command_margin(loop.feasible, q[i], v[i], a[i]) for i in range(q.shape[0])]
    outside = np.isneginf(expected_state)
    assert outside.any() and not outside.all(), "the sample must hold states inside and outside Q_a"
    np.testing.assert_array_equal(np.isneginf(state), outside)
    np.testing.assert_allclose(state, expected_state, rtol=0, atol=REACH_TOL)
    np.testing.assert_allclose(command, expected_command, rtol=0, atol=REACH_TOL)


@pytest.mark.parametrize("name,which", CASES)
def test_fallback_acceleration_equals_the_scalar_fallback(name, which):
    _, backup, batch, _ = _case(name, which)
    _, v, _ = _states(np.random.default_rng(13), 300)
    got = batch.fallback_acceleration(v.T)
    expected = np.stack([backup.fallback_acceleration(v[i]) for i in range(v.shape[0])], axis=1)
    assert (expected == 0.0).any() and (expected != 0.0).any()
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=0)


def _governed_alike(rng, batch, theta, q, v, u, slack, scalar):
    """The batched governor against `scalar(i, hint)` robot by robot: cold, then told a last λ for each
    robot (`_hints`); the same λ and the same commands both times. Returns the scalar results told."""
    hint = None
    for _ in range(2):
        sent, share = batch.govern(theta, q.T, v.T, u.T, DT, slack, hint)
        expected = [scalar(i, 0.0 if hint is None else hint[i]) for i in range(q.shape[0])]
        shares = np.array([g.share for g in expected])
        np.testing.assert_array_equal(share == 0.0, shares == 0.0)
        np.testing.assert_allclose(share, shares, rtol=1e-12, atol=0)
        np.testing.assert_allclose(sent, np.stack([g.u for g in expected], axis=1), rtol=0, atol=FORCE_TOL)
        hint = _hints(rng, shares)
    return expected


@pytest.mark.parametrize("name,which,kernel", _kernels(GOVERNED))
def test_the_governor_equals_the_scalar_governor_robot_by_robot(name, which, kernel):
    """Each robot its own plant (three masses), its own λ; the command as asked where it is backup-safe
    and where not even u_g is, the regula falsi's point elsewhere."""
    loop, backup, batch, _ = _case(name, which, kernel)
    rng = np.random.default_rng(14)
    N = 400
    q, v, _ = _states(rng, N)
    u = rng.uniform(-60.0, 60.0, (N, 3))
    plants = [OmniRobot(OmniRobotParameters(mass=m)) for m in (6.0, 9.85, 15.0)]
    plant_of = rng.integers(0, len(plants), N)
    theta = np.stack([plants[p].theta for p in plant_of], axis=1)
    expected = _governed_alike(rng, batch, theta, q, v, u, None, lambda i, hint: govern(
        backup, plants[plant_of[i]], loop.feasible, q[i], v[i], u[i], DT, hint=hint))
    kept = sum(g.share == 0.0 and g.feasible for g in expected)
    moved = sum(g.share > 0.0 for g in expected)
    hopeless = sum(not g.feasible for g in expected)
    assert min(kept, moved, hopeless) >= 5, (kept, moved, hopeless)


@pytest.mark.parametrize("held", [False, True], ids=["state", "operator_command_held"])
@pytest.mark.parametrize("name,which,kernel", _kernels(CASES))
def test_speed_aware_rows_equal_the_scalar_rows(name, which, kernel, held):
    loop, backup, batch, stacked = _case(name, which, kernel)
    q, v, a = _states(np.random.default_rng(15), 400)
    feasible, far = loop.feasible, loop.sharing.bands.b2
    x = (batch.row_K @ q.T) + batch.row_T
    got = batch.speed_aware_rows(x, v.T, far, a.T if held else None)[stacked]
    moved_robots = 0
    for i in range(q.shape[0]):
        rows = feasible.row_values(q[i], v[i])
        expected = speed_aware_rows(backup, feasible, rows, v[i], far, a[i] if held else None)
        moved_robots += expected[0] != rows[0]
        np.testing.assert_allclose(got[:, i], expected[0], rtol=0, atol=REACH_TOL, err_msg=f"robot {i}")
        np.testing.assert_array_equal(got[:, i] < 0.0, np.array(rows[0]) < 0.0)
    assert 0 < moved_robots < q.shape[0], "the sample must hold robots whose rows move and robots whose rows do not"


OMNI = [("paper_convex", "omni"), ("paper_nonconvex", "omni")]


def _slacks(rng, N):
    """Per robot a slack per block (translation m/s, yaw rad/s), some zero."""
    return rng.choice([0.0, 0.05, 0.15, 0.4], size=(2, N)) * np.array([[1.0], [3.0]])


@pytest.mark.parametrize("name,which", OMNI)
def test_reaches_and_margins_with_a_slack_equal_the_scalar_ones(name, which):
    loop, backup, batch, stacked = _case(name, which)
    rng = np.random.default_rng(16)
    q, v, a = _states(rng, 300)
    slack = _slacks(rng, 300)
    state = batch.state_reach(v.T, list(slack))[stacked]
    command = batch.command_reach(v.T, a.T, list(slack))[stacked]
    state_margin = batch.state_margin(q.T, v.T, list(slack))
    command_margin = batch.command_margin(q.T, v.T, a.T, list(slack))
    K = loop.feasible.row_matrix
    for i in range(v.shape[0]):
        np.testing.assert_allclose(state[:, i], backup.state_reach(K, v[i], slack[:, i]), rtol=0, atol=REACH_TOL)
        np.testing.assert_allclose(command[:, i], backup.command_reach(K, v[i], a[i], slack[:, i]), rtol=0,
                                   atol=REACH_TOL)
        assert state_margin[i] == pytest.approx(backup.state_margin(loop.feasible, q[i], v[i], slack[:, i]),
                                                abs=REACH_TOL)
        assert command_margin[i] == pytest.approx(
            backup.command_margin(loop.feasible, q[i], v[i], a[i], slack[:, i]), abs=REACH_TOL)


@pytest.mark.parametrize("name,which,kernel", _kernels(OMNI))
def test_the_governor_with_a_slack_equals_the_scalar_governor_robot_by_robot(name, which, kernel):
    loop, backup, batch, _ = _case(name, which, kernel)
    rng = np.random.default_rng(17)
    N = 400
    q, v, _ = _states(rng, N)
    slack = _slacks(rng, N)
    u = rng.uniform(-60.0, 60.0, (N, 3))
    model = OmniRobot()
    theta = np.repeat(model.theta[:, None], N, axis=1)
    expected = _governed_alike(rng, batch, theta, q, v, u, list(slack), lambda i, hint: govern(
        backup, model, loop.feasible, q[i], v[i], u[i], DT, slack[:, i], hint=hint))
    moved = sum(g.share > 0.0 and g.feasible for g in expected)
    hopeless = sum(not g.feasible for g in expected)
    assert min(moved, hopeless) >= 5, (moved, hopeless)


@pytest.mark.parametrize("held", [False, True], ids=["state", "operator_command_held"])
@pytest.mark.parametrize("name,which,kernel", _kernels(OMNI))
def test_speed_aware_rows_with_a_slack_equal_the_scalar_rows(name, which, kernel, held):
    loop, backup, batch, stacked = _case(name, which, kernel)
    rng = np.random.default_rng(18)
    q, v, a = _states(rng, 400)
    slack = _slacks(rng, 400)
    feasible, far = loop.feasible, loop.sharing.bands.b2
    x = (batch.row_K @ q.T) + batch.row_T
    got = batch.speed_aware_rows(x, v.T, far, a.T if held else None, list(slack))[stacked]
    for i in range(q.shape[0]):
        rows = feasible.row_values(q[i], v[i])
        expected = speed_aware_rows(backup, feasible, rows, v[i], far, a[i] if held else None, slack[:, i])
        np.testing.assert_allclose(got[:, i], expected[0], rtol=0, atol=REACH_TOL, err_msg=f"robot {i}")


def test_a_batch_refuses_robots_with_different_backup_models():
    loop = _loop("paper_convex")
    q0, v0 = np.array([[-0.5, 3.0, 0.0]] * 2), np.zeros((2, 3))
    for other in (None, dataclasses.replace(loop.backup, hold=0.2)):
        with pytest.raises(ValueError, match="robot 1: backup differs"):
            BatchProblem.from_loops([loop, dataclasses.replace(loop, backup=other)], q0, v0)
    assert BatchProblem.from_loops([loop, dataclasses.replace(loop)], q0, v0).backup == loop.backup


@NUMBA
def test_the_compiled_governor_equals_the_numpy_governor_on_a_large_batch():
    """4096 robots, slack or none: the same robots moved, the same λ (both probe the same 2⁻¹² grid)."""
    loop, _, fast, _ = _case("paper_nonconvex", "omni", "compiled")
    slow = dataclasses.replace(fast, compiled=None)
    rng = np.random.default_rng(19)
    N = 4096
    q, v, _ = _states(rng, N)
    u = rng.uniform(-60.0, 60.0, (N, 3))
    theta = np.repeat(OmniRobot().theta[:, None], N, axis=1)
    for slack in (None, list(_slacks(rng, N))):
        hint = None
        for _ in range(2):
            sent, share = fast.govern(theta, q.T, v.T, u.T, DT, slack, hint)
            sent_np, share_np = slow.govern(theta, q.T, v.T, u.T, DT, slack, hint)
            np.testing.assert_array_equal(share, share_np)
            np.testing.assert_allclose(sent, sent_np, rtol=0, atol=FORCE_TOL)
            assert 0.1 < np.mean((share > 0.0) & (share < 1.0)) < 0.9
            hint = _hints(rng, share)


def test_a_stop_without_a_compiled_form_keeps_the_numpy_governor():
    loop = _loop("paper_convex")
    table = GroupTable.of(loop.feasible)
    assert BackupTable.of(PLAIN, loop.feasible, table).compiled is None
    with pytest.raises(ValueError, match="no compiled governor"):
        BackupTable.of(PLAIN, loop.feasible, table, compiled=True)
