"""Small builders shared by the control-core tests."""
from __future__ import annotations

import math

import numpy as np

from sharedctl.constraints import FeasibleSet, Polytope
from sharedctl.human import LineTrajectory, ScriptedOperator
from sharedctl.models import OmniRobot
from sharedctl.reference import ReferenceShape
from sharedctl.sharing import Mode, SharingParameters
from sharedctl.simulator import ClosedLoop, make_controller

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
