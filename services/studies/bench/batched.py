"""The batched simulator (sharedctl.batched) against the scalar simulator, side by side in one run.

The workload is a Monte-Carlo fleet on the adversarial-wall scenario (the paper's convex set:
5 faces, 4 constraint groups; the CE configuration): every robot starts at its own random state
just below the wall y = 4, moving towards it, and is driven by its own adversarial operator
(random target beyond the wall, gain and deflection), so the machine takes over during the run —
the full step (plant, law, sharing) is exercised, not just the operator's path.

The scalar simulator (simulator.simulate) runs robots of the same fleet, one at a time, in the
same process, interleaved with the batched runs so both see the same machine load; each
figure is the median over the repeats. Robot-steps/s = robots × steps / wall time.
`steps_per_s` splits the fleet over one process per core (the machine has 2; the split is the
batch's `take`, the core itself is single-threaded); `one_process` gives the same figures for
a single process and `cpu` the rates per second of process CPU time (what the simulators get
on a busy machine, where wall time also counts other people's work).

`python -m sharedctl.services.studies.bench.batched [--quick]` prints the headline figure and the
scaling tables (robots, constraint groups) in Markdown.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import multiprocessing
import os
import time
import tomllib
from importlib import resources

import numpy as np

from sharedctl.batched import BatchProblem, OperatorBatch, simulate_batch
from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.human import AdversarialOperator, LineTrajectory
from sharedctl.scenario import parse
from sharedctl.simulator import ClosedLoop, simulate

DT = 0.001
# 8192 robots is 4096 per process: below ~4096 a process's rate still grows with the batch (the
# per-step Python cost is shared by fewer robots; `scaling` gives the table), and a Monte-Carlo
# campaign has thousands of seeds
QUICK = {"robots": 8192, "seconds": 0.2, "repeats": 3, "scalar_robots": 2}
FULL = {"robots": 16384, "seconds": 0.3, "repeats": 3, "scalar_robots": 3}


def _loop(controller: str = "ce") -> ClosedLoop:
    data = tomllib.loads(resources.files("sharedctl").joinpath("scenarios/adversarial_wall.toml").read_text())
    return parse(data).closed_loop(controller)[0]


def fleet(loop: ClosedLoop, robots: int, seed: int = 1) -> BatchProblem:
    """`robots` random robots and adversaries on `loop`'s scenario (the adversarial wall's layout)."""
    rng = np.random.default_rng(seed)
    q0 = np.column_stack([rng.uniform(-0.8, 0.8, robots), rng.uniform(3.75, 3.95, robots),
                          rng.uniform(-0.8, 0.8, robots)])
    v0 = np.column_stack([rng.uniform(-0.3, 0.3, robots), rng.uniform(0.2, 0.8, robots),
                          rng.uniform(-0.3, 0.3, robots)])
    target = np.vstack([rng.uniform(-1.5, 1.5, robots), rng.uniform(4.3, 6.0, robots), rng.uniform(-1.0, 1.0, robots)])
    kp = np.broadcast_to(rng.uniform(10.0, 40.0, robots), (3, robots))
    operators = OperatorBatch.adversaries(kp, target, rng.uniform(0.3, 1.5, robots))
    return BatchProblem.replicate(loop, q0, v0, operators)


def _scalar_loop(loop: ClosedLoop, problem: BatchProblem, i: int) -> ClosedLoop:
    ops = problem.operators
    target = ops.target[:, i].copy()
    human = AdversarialOperator(LineTrajectory(target, np.zeros(3)), ops.kp[:, i].copy(), target,
                                float(ops.deflection[i]))
    return ClosedLoop(loop.model, loop.feasible, human, loop.controller, loop.sharing, loop.reference,
                      loop.theta_hat0, loop.backup)


def _scalar_rate(loop: ClosedLoop, problem: BatchProblem, robots: int, seconds: float) -> tuple[float, float]:
    """(steps/s of wall time, of process CPU time) of simulator.simulate on robots of the fleet."""
    steps = 0
    wall, cpu = time.perf_counter(), time.process_time()
    for i in range(robots):
        trace = simulate(_scalar_loop(loop, problem, i), problem.q0[:, i], problem.v0[:, i], seconds, DT)
        steps += trace.t.size
    return steps / (time.perf_counter() - wall), steps / max(time.process_time() - cpu, 1e-9)


def _run_part(args) -> tuple[int, float]:
    problem, seconds, chunk = args
    cpu = time.process_time()
    result = simulate_batch(problem, seconds, DT, chunk=chunk)
    return int(result.steps.sum()), time.process_time() - cpu


def _batch_rate(problem: BatchProblem, seconds: float, chunk: int = 8192, pool=None,
                parts: int = 1) -> tuple[float, float]:
    """(robot-steps/s of wall time, of CPU time summed over the processes); `pool` runs `parts` slices at once."""
    slices = [problem.take(idx) for idx in np.array_split(np.arange(problem.size), parts)]
    wall = time.perf_counter()
    if pool is None:
        done = [_run_part((part, seconds, chunk)) for part in slices]
    else:
        done = pool.map(_run_part, [(part, seconds, chunk) for part in slices])
    elapsed = time.perf_counter() - wall
    steps, cpu = sum(d[0] for d in done), sum(d[1] for d in done)
    return steps / elapsed, steps / max(cpu, 1e-9)


def measure_batched(quick: bool) -> dict:
    """{"robots", "steps_per_s", "scalar_steps_per_s", "speedup_vs_scalar"} (+ "processes", "one_process",
    "without_backup" — the same fleet and processes without the fail-safe stop's governor —, "cpu"):
    medians over interleaved repeats."""
    p = QUICK if quick else FULL
    loop = _loop()
    problem = fleet(loop, p["robots"])
    bare = fleet(dataclasses.replace(loop, backup=None), p["robots"])    # the same fleet without the governor
    workers = max(1, min(os.cpu_count() or 1, 2))
    scalar, one, many, without = [], [], [], []
    # spawn, not fork: the caller may hold threads (Zenoh, CAN) that a forked child must not inherit
    with multiprocessing.get_context("spawn").Pool(workers) as pool:
        pool.map(_run_part, [(problem.take(slice(0, 8)), 10 * DT, 8)] * workers)    # start-up outside the timing
        for _ in range(p["repeats"]):
            scalar.append(_scalar_rate(loop, problem, p["scalar_robots"], p["seconds"]))
            one.append(_batch_rate(problem, p["seconds"]))
            many.append(_batch_rate(problem, p["seconds"], pool=pool, parts=workers))
            without.append(_batch_rate(bare, p["seconds"], pool=pool, parts=workers))

    def med(rows, k):
        return float(np.median([r[k] for r in rows]))

    scalar_rate = med(scalar, 0)
    return {
        "robots": p["robots"], "steps_per_s": med(many, 0), "scalar_steps_per_s": scalar_rate,
        "speedup_vs_scalar": med(many, 0) / scalar_rate, "processes": workers,
        "one_process": {"steps_per_s": med(one, 0), "speedup_vs_scalar": med(one, 0) / scalar_rate},
        "without_backup": {"steps_per_s": med(without, 0)},
        "cpu": {"steps_per_s": med(many, 1), "one_process_steps_per_s": med(one, 1),
                "scalar_steps_per_s": med(scalar, 1), "speedup_vs_scalar": med(one, 1) / med(scalar, 1)},
    }


# ----- scaling (for docs/performance.md) -------------------------------------------------------
def polygon_loop(sides: int, controller: str = "ce") -> ClosedLoop:
    """The adversarial-wall loop on a regular `sides`-gon in (x, y) (inradius 2 around (0, 2)) with |ψ| < π/2."""
    base = _loop(controller)
    rows = [[math.cos(a), math.sin(a), 0.0] for a in (2.0 * math.pi * k / sides + math.pi / 2 for k in range(sides))]
    K = np.array(rows + [[0, 0, 1], [0, 0, -1]], float)
    centre = np.array([0.0, 2.0, 0.0])
    T = np.concatenate([-(2.0 + K[:sides] @ centre), [-math.pi / 2, -math.pi / 2]])
    feasible = FeasibleSet.from_regions([Polytope.from_rows(K, T)])
    return ClosedLoop(base.model, feasible, base.human, base.controller, base.sharing, base.reference,
                      base.theta_hat0, base.backup)


def scaling(quick: bool = True) -> dict:
    """Robot-steps/s against the number of robots (paper's convex set) and of constraint groups (polygons)."""
    seconds = 0.1 if quick else 0.3
    loop = _loop()
    by_robots = []
    for robots in (256, 1024, 2048, 4096, 8192, 16384):
        wall, cpu = _batch_rate(fleet(loop, robots), seconds)
        by_robots.append({"robots": robots, "groups": len(loop.feasible.groups), "steps_per_s": wall,
                          "cpu_steps_per_s": cpu})
    by_groups = []
    for sides in (4, 6, 8, 12):
        poly = polygon_loop(sides)
        wall, cpu = _batch_rate(fleet(poly, 4096), seconds)
        by_groups.append({"robots": 4096, "groups": len(poly.feasible.groups), "steps_per_s": wall,
                          "cpu_steps_per_s": cpu})
    return {"by_robots": by_robots, "by_groups": by_groups}


def _table(rows) -> str:
    out = ["| robots | groups | robot-steps/s (wall) | robot-steps/s (process CPU) |", "|---:|---:|---:|---:|"]
    out += [f"| {r['robots']} | {r['groups']} | {r['steps_per_s']:,.0f} | {r['cpu_steps_per_s']:,.0f} |" for r in rows]
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    print(measure_batched(args.quick))
    table = scaling(args.quick)
    print(_table(table["by_robots"]))
    print()
    print(_table(table["by_groups"]))


if __name__ == "__main__":
    main()
