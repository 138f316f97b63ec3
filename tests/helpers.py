"""Small builders shared by the control-core tests."""
from __future__ import annotations

import fcntl
import functools
import math
import os
import pickle

import numpy as np

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.human import LineTrajectory, ScriptedOperator
from sharedctl.models import OmniRobot
from sharedctl.reference import ReferenceShape
from sharedctl.sharing import Mode, SharingParameters
from sharedctl.simulator import ClosedLoop, make_controller, simulate

HALF_PI = math.pi / 2

#: the paper's convex set: x ≥ −1, 0.5 ≤ y ≤ 4, |ψ| < π/2
PAPER_CONVEX_K = [[-1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1]]
PAPER_CONVEX_T = [-1, 0.5, -4, -HALF_PI, -HALF_PI]

#: one group of the paper's convex set: x ≥ −1, y ≤ 4, ψ ≤ π/2 (READING.md's check)
WALL_K = [[-1, 0, 0], [0, 1, 0], [0, 0, 1]]
WALL_T = [-1, -4, -HALF_PI]


def omni_loop(K, T, trajectory, controller="ce", mode=Mode.MACHINE, gains=None, human=None, **sharing):
    model = OmniRobot()
    feasible = FeasibleSet.from_regions([Polytope.from_rows(K, T)])
    human = human or ScriptedOperator(trajectory, np.full(3, 20.0), np.full(3, 12.0))
    return ClosedLoop(
        model, feasible, human, make_controller(controller, gains), SharingParameters(mode=mode, **sharing),
        ReferenceShape(),
    )


def line(start, velocity):
    return LineTrajectory(np.asarray(start, float), np.asarray(velocity, float))


#: the folder the test processes of one `pytest` run share (tests/conftest.py sets it; none: no sharing)
RUN_CACHE_VARIABLE = "SHAREDCTL_TEST_RUN_CACHE"


@functools.lru_cache(maxsize=None)
def packaged_run(name: str, controller: str):
    """The run `sharedctl sim NAME --controller C` makes (the packaged scenario, its duration and step): (trace, dt).

    Computed once per `pytest` run: the first test process that needs it computes it while holding a lock, the
    others (xdist workers) wait for it and read it back from the run's own folder. A test reads a trace, never
    changes it."""
    folder = os.environ.get(RUN_CACHE_VARIABLE)
    if not folder:
        return _simulate_packaged(name, controller)
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, f"{name}-{controller}.pickle")
    with open(path + ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if os.path.exists(path):
            with open(path, "rb") as f:
                return pickle.load(f)
        run = _simulate_packaged(name, controller)
        with open(path + ".part", "wb") as f:
            pickle.dump(run, f)
        os.replace(path + ".part", path)
        return run


def _simulate_packaged(name: str, controller: str):
    from sharedctl.services.scenario_files import load

    scenario = load(name)
    loop, q0, v0 = scenario.closed_loop(controller)
    return simulate(loop, q0, v0, scenario.duration, scenario.dt), scenario.dt
