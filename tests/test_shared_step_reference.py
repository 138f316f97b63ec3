"""The shared controller's step reproduces its recorded reference outputs (tests/fixtures).

The fixture holds closed-loop trajectories (tests/fixtures/make_shared_step_reference.py): the ce
and of runs recorded before the step's hot path was optimised, the nce runs with the composite law
of docs/control.md §4.2 (`--laws nce`). Replaying the recorded (q, q̇) open loop through
`SharedController.step`, every output must match to 1e-12 relative (scaled by the signal's
largest magnitude), and every discrete decision exactly.
"""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sharedctl.scenario import parse
from sharedctl.shared_controller import OperatorInput, SharedController

FIXTURE = Path(__file__).parent / "fixtures" / "shared_step_reference.npz"
RTOL = 1e-12
CONTINUOUS = ("u_s", "u_f", "theta_hat", "q_r", "k_h")
DISCRETE = ("authority", "group", "role", "set_class")


def _runs():
    with np.load(FIXTURE) as data:
        meta = json.loads(str(data["meta"]))
        arrays = {k: data[k] for k in data.files if k != "meta"}
    return meta["period"], [(run, {s: arrays[f"{run['key']}/{s}"] for s in CONTINUOUS + DISCRETE + ("q", "v")})
                            for run in meta["runs"]]


PERIOD, RUNS = _runs()


def replay(run, recorded):
    loop, q0, _ = parse(run["scenario"]).closed_loop(run["law"])
    # recorded with the release in the safe set whatever the push (tests/test_handover.py holds the hold rule)
    sharing = replace(loop.sharing, hold_pushed_faces=False)
    ctrl = SharedController(loop.model, loop.feasible, loop.controller, sharing, loop.reference)
    state = ctrl.initial_state(q0, loop.theta_hat0)
    feedback = loop.controller.observer is None
    got = {s: [] for s in CONTINUOUS + DISCRETE}
    for k in range(run["samples"]):
        t, q, v = k * PERIOD, recorded["q"][k], recorded["v"][k]
        cmd = loop.human.command(t, q, v)
        operator = OperatorInput(loop.human.desired(t), cmd.force, cmd.intent)
        state, out = ctrl.step(state, q, v if feedback else None, operator, PERIOD)
        got["u_s"].append(out.u_s)
        got["u_f"].append(out.u_f)
        got["theta_hat"].append(out.theta_estimate)
        got["q_r"].append(out.q_r)
        got["k_h"].append(out.k_h)
        got["authority"].append(int(out.authority))
        got["group"].append(-1 if out.group is None else out.group)
        got["role"].append(int(out.role))
        got["set_class"].append(int(out.set_class))
    return {k: np.asarray(v) for k, v in got.items()}


def test_the_fixture_exercises_every_law_and_hand_overs():
    laws = {run["law"] for run, _ in RUNS}
    assert laws == {"ce", "nce", "of"}
    for law in laws:      # take-overs and releases, at least two excursions' worth for every law
        assert sum(int(np.count_nonzero(np.diff(rec["authority"] == 0))) for run, rec in RUNS if run["law"] == law) >= 4
    assert any(np.any(rec["role"] == 1) for _, rec in RUNS) and any(np.any(rec["authority"] == 1) for _, rec in RUNS)


@pytest.mark.parametrize("run,recorded", RUNS, ids=[run["key"] for run, _ in RUNS])
def test_step_reproduces_the_recorded_outputs(run, recorded):
    got = replay(run, recorded)
    for signal in DISCRETE:
        np.testing.assert_array_equal(got[signal], recorded[signal], err_msg=signal)
    for signal in CONTINUOUS:
        want = recorded[signal]
        scale = np.nanmax(np.abs(want)) if np.any(np.isfinite(want)) else 1.0
        np.testing.assert_allclose(got[signal], want, rtol=RTOL, atol=RTOL * max(scale, 1e-300), equal_nan=True,
                                   err_msg=signal)
