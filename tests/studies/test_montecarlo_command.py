"""`sharedctl faults montecarlo` end to end on a local Dask cluster: the figures depend on the seed only,
not on the number of workers; a planted unsafe configuration (robots without brakes, controllers killed)
is found, every counterexample saved as a scenario `sharedctl sim` loads, and one replayed in the real
processes (`sharedctl demo`) leaves the set there too."""
from __future__ import annotations

import json

import pytest

from sharedctl.scenario import parse
from sharedctl.services.cli import main

pytestmark = pytest.mark.processes

TIMINGS = ("runs_per_s", "wall_seconds", "workers", "cluster_startup_seconds", "command")


def _run(tmp_path, name, *options):
    out = tmp_path / f"{name}.json"
    code = main(["faults", "montecarlo", "--seed", "3", "--json", str(out), *options])
    return code, json.loads(out.read_text())


def test_one_and_two_workers_give_the_same_figures(tmp_path):
    options = ("--runs", "6", "--chunk-runs", "2", "--duration", "0.4", "--families", "can,operator,mismatch")
    code1, one = _run(tmp_path, "one", *options, "--workers", "1")
    code2, two = _run(tmp_path, "two", *options, "--workers", "2")
    assert code1 == code2 == 0
    assert (one["workers"], two["workers"]) == (1, 2)
    assert {k: v for k, v in one.items() if k not in TIMINGS} == {k: v for k, v in two.items() if k not in TIMINGS}
    assert [f["family"] for f in one["families"]] == ["can", "operator", "mismatch"]


def test_robots_without_brakes_leave_the_set_after_a_kill_and_each_case_is_saved(tmp_path):
    report = tmp_path / "report"
    code, out = _run(tmp_path, "planted", "--runs", "8", "--chunk-runs", "8", "--families", "kill",
                     "--brake-torque", "0", "--duration", "3.5", "--workers", "1", "--report", str(report),
                     "--replay", "1")
    assert code == 0                       # robots without brakes are outside the envelope: found, not claimed
    assert out["violations"] > 0 and out["violations_inside_envelope"] == 0
    assert out["families"][0]["upper_95"] > out["violations"] / out["runs"]
    saved = sorted((report / "counterexamples").glob("run-*.toml"))
    assert len(saved) == out["violations"]
    import tomllib
    scenario = parse(tomllib.loads(saved[0].read_text()))
    assert scenario.closed_loop()[0].feasible.regions
    assert "controller.kill_at=" in saved[0].read_text()
    # replayed once in the real processes: the robot without brakes, its controller killed, leaves the set there too
    (replayed,) = out["replays"]
    assert replayed["run"] == out["counterexamples"][0]["run"] and replayed["error"] is None, replayed
    assert replayed["real_violations"] > 0 and replayed["real_min_margin"] < 0, replayed
