"""Cost of one control step, `SharedController.step`, and where it goes.

The step is timed along a closed-loop trajectory of the adversarial-wall scenario (the paper's
convex set: 5 faces, 4 constraint groups, all evaluated every step; the operator pushes into a
face, so the machine takes over and hands back several times), replayed open loop through a
fresh controller with perf_counter_ns around each call. Figures per law: every step, the steps
where a machine law runs (the headline: the safety-relevant path) and the steps left to the
operator. Also: a per-part breakdown at one engaged state, the per-call costs that set the
floor, a cProfile summary, and how the step scales with the number of constraint groups.
"""
from __future__ import annotations

import cProfile
import copy
import io
import pstats
import time
import tomllib
from importlib import resources

import numpy as np

from sharedctl.sampled import simulate_sampled
from sharedctl.scenario import parse
from sharedctl.sharing import Authority, arbitrate, operator_pushes, push_turned_away
from sharedctl.shared_controller import OperatorInput, SharedController
from sharedctl.transform import all_groups, coordinates

from .statistics import percentiles

PERIOD = 0.002
LAWS = ("ce", "nce", "of")


def _scenario(name: str = "adversarial_wall") -> dict:
    return tomllib.loads(resources.files("sharedctl").joinpath(f"scenarios/{name}.toml").read_text())


def _replay_inputs(data: dict, law: str, seconds: float):
    loop, q0, v0 = parse(data).closed_loop(law)
    trace = simulate_sampled(loop, q0, v0, seconds, PERIOD)
    inputs = []
    for k in range(len(trace.t)):
        t = k * PERIOD
        cmd = loop.human.command(t, trace.q[k], trace.v[k])
        inputs.append((trace.q[k], trace.v[k], OperatorInput(loop.human.desired(t), cmd.force, cmd.intent)))
    controller = SharedController(loop.model, loop.feasible, loop.controller, loop.sharing, loop.reference, loop.backup)
    return loop, q0, controller, inputs


def _run(loop, q0, controller, inputs, clock=time.perf_counter_ns):
    feedback = loop.controller.observer is None
    state = controller.initial_state(q0, loop.theta_hat0)
    elapsed, engaged = np.empty(len(inputs)), np.empty(len(inputs), dtype=bool)
    step = controller.step
    for k, (q, v, operator) in enumerate(inputs):
        t0 = clock()
        state, out = step(state, q, v if feedback else None, operator, PERIOD)
        elapsed[k] = clock() - t0
        engaged[k] = out.authority is not Authority.HUMAN
    return elapsed / 1e3, engaged


def step_times(law: str, seconds: float, repeats: int) -> dict:
    """µs per step along the trajectory: headline (machine engaged) median/p99, plus all and human-only."""
    return interleaved_step_times((law,), seconds, repeats)[law]


def interleaved_step_times(laws, seconds: float, repeats: int) -> dict:
    """`step_times` of several laws measured in turns: round r replays every law once, so a slow spell
    of the host (a neighbour on the hypervisor, another job) falls on every law alike rather than on
    whichever law was being timed. Each law is replayed once untimed first (caches, branch paths). With
    ce, the scenario is also replayed with `[backup] enabled = false`, in the same rounds:
    `ce.without_backup`, the price of the backup-safe checks in the same run (its own closed loop: on the
    backup-safe loop's states, farther from the wall, the paper's loop would not engage at all)."""
    replays = {law: _replay_inputs(_scenario(), law, seconds) for law in laws}
    if "ce" in replays:                 # the same scenario without the fail-safe stop, in the same rounds
        replays[_WITHOUT_BACKUP] = _replay_inputs(dict(_scenario(), backup={"enabled": False}), "ce", seconds)
    for replay in replays.values():
        _run(*replay)                                        # warm-up
    runs = {name: [] for name in replays}
    for _ in range(repeats):
        for name in replays:
            runs[name].append(_run(*replays[name]))
    result = {}
    for law in replays:
        times = np.concatenate([r[0] for r in runs[law]])
        engaged = np.concatenate([r[1] for r in runs[law]])
        head = percentiles(times[engaged])
        cpu, cpu_engaged = _run(*replays[law], clock=time.thread_time_ns)   # CPU time: what load does not add
        result[law] = {
            "median": head["median"], "p99": head["p99"], "steps": int(engaged.sum()),
            "thread_cpu_median": float(np.median(cpu[cpu_engaged])) if cpu_engaged.any() else None,
            "round_medians": [float(np.median(r[0][r[1]])) if r[1].any() else None for r in runs[law]],
            "all": _brief(percentiles(times)), "operator_only": _brief(percentiles(times[~engaged])),
        }
    if _WITHOUT_BACKUP in result:
        result["ce"]["without_backup"] = result.pop(_WITHOUT_BACKUP)
    return result


_WITHOUT_BACKUP = "ce without the backup"


def _brief(stats: dict) -> dict:
    return {"median": stats["median"], "p99": stats["p99"], "steps": stats["n"]}


def _median_us(fn, repeats: int) -> float:
    samples = np.empty(repeats)
    for i in range(repeats):
        t0 = time.perf_counter_ns()
        fn()
        samples[i] = time.perf_counter_ns() - t0
    return float(np.median(samples) / 1e3)


def breakdown(law: str = "ce", repeats: int = 2000) -> dict:
    """µs of each part of one step at an engaged state of the trajectory (medians of `repeats` calls)."""
    loop, q0, controller, inputs = _replay_inputs(_scenario(), law, 3.0)
    feedback = loop.controller.observer is None
    state = controller.initial_state(q0, loop.theta_hat0)
    chosen = None
    for q, v, operator in inputs:
        before = state
        state, out = controller.step(state, q, v if feedback else None, operator, PERIOD)
        if out.authority is Authority.MACHINE and state.law_role is not None and before.law_role is state.law_role:
            chosen = (before, q, v, operator)
            break
    if chosen is None:
        return {}
    state, q, v, operator = chosen
    feasible, reference, machine = loop.feasible, loop.reference, loop.controller
    v_used = v if feedback else machine.observer.velocity(q, state.observer)
    q_list, v_list = q.tolist(), v_used.tolist()
    rows = feasible.row_values(q_list, v_list)
    values = all_groups(feasible.stack, q, v_used, operator.desired, reference, machine.tracking.lam)[1].tolist()
    grp = feasible.groups[state.arbiter.group]
    group_rows = feasible.group_rows(state.arbiter.group, rows)
    c = coordinates(grp, q_list, v_list, operator.desired, reference, group_rows)
    law_ = machine.law(state.law_role)
    parts = {
        "row_values": lambda: feasible.row_values(q_list, v_list),
        "arbitrate": lambda: _arbitrate(feasible, loop.sharing, state.arbiter, q, v_used, operator, values, rows,
                                        reference),
        "coordinates": lambda: coordinates(grp, q_list, v_list, operator.desired, reference, group_rows),
        "law_evaluate": lambda: law_.evaluate(loop.model, grp, c, q, v_used, state.theta_hat, state.law_state),
        "region_margins": lambda: feasible.region_margins(q, rows[0]),
        # only on samples that select a group (take-over, operator in charge): not in this one
        "all_groups_on_demand": lambda: all_groups(feasible.stack, q, v_used, operator.desired, reference,
                                                   machine.tracking.lam),
        "whole_step": lambda: controller.step(state, q, v if feedback else None, operator, PERIOD),
    }
    return {name: _median_us(fn, repeats) for name, fn in parts.items()}


def _arbitrate(feasible, sharing, arbiter, q, v_used, operator, values, rows, reference):
    """The step's sharing function (SharedController.step): the operator's pushes, push_turned_away, arbitrate."""
    pushes = operator_pushes(feasible, operator.force)
    away = push_turned_away(feasible, q.tolist(), operator.desired.q, operator.force, reference.epsilon,
                            sharing.bands, rows[0], pushes)
    return arbitrate(feasible, sharing, arbiter, q, v_used, operator.intent, PERIOD, values.__getitem__,
                     [True] * len(values), rows, away, pushes, float(np.dot(v_used, operator.force)))


def floors(batches: int = 200, batch: int = 100) -> dict:
    """ns per call of the smallest operations the step is made of: the floor under any rewrite.
    The least mean over `batches` batches of `batch` calls (robust to other load on the machine)."""
    K, q = np.random.default_rng(0).standard_normal((3, 3)), np.ones(3)
    a, b = 1.25, 0.5
    setups = {
        "python_call_ns": lambda: None,
        "numpy_ufunc_3_ns": lambda: np.add(q, q),
        "numpy_matvec_3x3_ns": lambda: K @ q,
        "numpy_reduction_3_ns": lambda: q.sum(),
        "numpy_array_from_list_ns": lambda: np.array([a, b, a]),
        "python_float_op_ns": lambda: a * b + a,
    }
    out = {}
    for name, fn in setups.items():
        best = float("inf")
        for _ in range(batches):
            t0 = time.perf_counter_ns()
            for _ in range(batch):
                fn()
            best = min(best, (time.perf_counter_ns() - t0) / batch)
        out[name] = best
    empty = out["python_call_ns"]
    return {name: (value if name == "python_call_ns" else max(value - empty, 0.0)) for name, value in out.items()}


def profile_summary(law: str = "ce", seconds: float = 4.0, top: int = 14) -> str:
    """cProfile of the step along the trajectory, sorted by own time: the first `top` lines."""
    loop, q0, controller, inputs = _replay_inputs(_scenario(), law, seconds)
    profiler = cProfile.Profile()
    profiler.enable()
    _run(loop, q0, controller, inputs)
    profiler.disable()
    text = io.StringIO()
    stats = pstats.Stats(profiler, stream=text).strip_dirs().sort_stats("tottime")
    stats.print_stats(top)
    lines = [line for line in text.getvalue().splitlines() if line.strip()]
    start = next((i for i, line in enumerate(lines) if "ncalls" in line), 0)
    return "\n".join(lines[start - 1 if start else 0:])


def scaling(group_counts=(1, 2, 4, 8, 16), law: str = "ce", repeats: int = 3) -> list[dict]:
    """Step cost against the number of constraint groups G: G overlapping orthant regions
    {x ≤ a_i, y ≤ b_i, ψ ≤ c_i} (one group each) around the convex scenario's trajectory."""
    base = _scenario()
    rows = []
    for groups in group_counts:
        data = copy.deepcopy(base)
        data["region"] = [
            {"K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
             "T": [-(1.5 + 0.1 * i), -(4.0 + 0.05 * i), -(1.5707963267948966 + 0.01 * i)]}
            for i in range(groups)
        ]
        data["initial"] = {"q": [0.0, 2.0, 0.0], "qdot": [0.0, 0.0, 0.0]}
        loop, q0, controller, inputs = _replay_inputs(data, law, 2.0)
        assert len(loop.feasible.groups) == groups
        _run(loop, q0, controller, inputs)
        runs = [_run(loop, q0, controller, inputs) for _ in range(repeats)]
        times = np.concatenate([r[0] for r in runs])
        engaged = np.concatenate([r[1] for r in runs])
        rows.append({"groups": groups, "median_us": float(np.median(times)), "p99_us": float(np.percentile(times, 99)),
                     "engaged_fraction": float(engaged.mean())})
    return rows


def measure(quick: bool) -> dict:
    seconds, repeats = (3.0, 6) if quick else (8.0, 10)
    return interleaved_step_times(LAWS, seconds, repeats)
