"""The hand-over on the packaged scenarios, whole (docs/control.md §6): an operator whose wish leaves the
set meets one take-over and at most one release per excursion, the operator has u_s = u_h in the safe
set, the applied force has no pulse train, and the wheel torques stay within the drives' limit — for
each of the three configurations."""
from __future__ import annotations

import numpy as np
import pytest

from sharedctl.metrics import FORCE_JUMP_SHARE, handover, summarize
from sharedctl.services.robot.plant import RobotSimConfig
from sharedctl.sharing import Authority

from .helpers import packaged_run

DRIVE_LIMIT = RobotSimConfig().torque_limit         # N·m per wheel, the simulated drives' clamp
run = packaged_run


CASES = [(name, c) for name in ("paper_convex", "paper_nonconvex") for c in ("ce", "nce", "of")]


@pytest.mark.parametrize("name,controller", CASES)
def test_a_wish_leaving_the_set_meets_one_take_over_and_at_most_one_release(name, controller):
    trace, dt = run(name, controller)
    figures = handover(trace)
    human = trace.authority == int(Authority.HUMAN)
    changes = np.flatnonzero(human[1:] != human[:-1]) + 1
    outside = ~trace.wish_inside
    first_out = np.flatnonzero(outside)[0]
    assert figures["excursions"] == 1
    assert 1 <= changes.size <= 2 and changes[0] >= first_out       # nothing before the wish leaves
    assert figures["max_switches_per_excursion"] == changes.size
    dwell = summarize(trace, dt)["min_dwell"]
    assert dwell is None or dwell >= 0.2


@pytest.mark.parametrize("name,controller", CASES)
def test_the_safe_set_is_transparent(name, controller):
    trace, dt = run(name, controller)
    assert summarize(trace, dt)["transparency"] >= 0.99


@pytest.mark.parametrize("name,controller", CASES)
def test_the_applied_force_jumps_only_where_authority_or_the_active_group_changes(name, controller):
    """A pulse train has two large jumps per pulse; here a take-over, a release, or the machine
    changing group (the robot slid along one face into another, near a corner) may make one, and
    nothing else does (a jump: more than FORCE_JUMP_SHARE of the run's peak |u_s| in one sample)."""
    trace, _ = run(name, controller)
    rows = trace.u_s
    jumps = np.flatnonzero(np.linalg.norm(np.diff(rows, axis=0), axis=1)
                           > FORCE_JUMP_SHARE * np.linalg.norm(rows, axis=1).max()) + 1
    human = trace.authority == int(Authority.HUMAN)
    changes = set((np.flatnonzero((human[1:] != human[:-1]) | (trace.group[1:] != trace.group[:-1])) + 1).tolist())
    assert jumps.size >= 1 and set(jumps.tolist()) <= changes
    assert handover(trace)["force_jumps"] == jumps.size


@pytest.mark.parametrize("name,controller", CASES)
def test_the_wheel_torques_stay_within_the_drives_limit(name, controller):
    trace, _ = run(name, controller)
    assert np.abs(trace.tau).max() <= DRIVE_LIMIT
    assert handover(trace)["peak_wheel_torque"] == np.abs(trace.tau).max()
