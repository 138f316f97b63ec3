"""End to end: `sharedctl demo --headless --json` runs robot, controller and scripted operator as processes.

Acceptance: the paper's convex (20 s) and non-convex (30 s) scenarios run with 0 ground-truth
violations and no emergency stop; the distributed run matches the in-process sampled
simulation of the same plant (`reference_plant`: SharedController.step at 500 Hz on the
robot's true plant with its wheel friction) within TOLERANCE (final (x, y) within 5 cm,
human-authority share within 0.1); every child exits with 0 within 2 s of SIGTERM (never
killed) and none is left. (`reference`, simulate_sampled with the model as plant, is reported
too; it has no friction, so in the non-convex run, which ends moving, it leads by ~0.2 m.)
"""
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sharedctl.services.demo.measure import TOLERANCE

from .processes import run_launcher

pytestmark = [pytest.mark.slow, pytest.mark.processes]
RUNS = {"paper_convex": 20.0, "paper_nonconvex": 30.0}
# The controller's CAN feedback timeout, relaxed from its default 50 ms: the simulated robot is a
# Python process, and on a shared 2-core host its encoder stream was measured to pause 45–70 ms
# (a passive listener on the bus, robot at nice −10), which trips 50 ms. 150 ms stays above the
# drives' own 0.1 s watchdog. What is under test is the distributed shared control.
FEEDBACK_TIMEOUT = ("--feedback-timeout-ms", "150")


def alive(pid: int) -> bool:
    """A process with this pid exists and is one of ours (a `sharedctl.services.cli` process)."""
    try:
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
    except (FileNotFoundError, ProcessLookupError):
        return False
    return b"sharedctl.services.cli" in cmdline


def run_demo(tmp_path: Path, *args: str, timeout: float = 150.0) -> tuple[subprocess.CompletedProcess, dict]:
    out = tmp_path / "demo.json"
    proc = run_launcher(
        [sys.executable, "-m", "sharedctl.services.cli", "demo", "--headless", "--json", str(out),
         "--log-dir", str(tmp_path / "logs"), *args],
        stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=timeout)
    summary = json.loads(out.read_text()) if out.exists() else {}
    return proc, summary


@pytest.fixture(scope="module", params=sorted(RUNS))
def demo(request, tmp_path_factory):
    scenario = request.param
    proc, summary = run_demo(tmp_path_factory.mktemp(scenario), "--scenario", scenario, *FEEDBACK_TIMEOUT)
    assert summary, f"no summary: {proc.stdout}\n{proc.stderr}"
    return scenario, proc, summary


def test_the_demo_exits_0(demo):
    _, proc, summary = demo
    assert proc.returncode == 0, f"{proc.stderr}\n{json.dumps(summary, indent=1)[:3000]}"
    assert summary["ok"]


def test_no_ground_truth_sample_leaves_the_feasible_set(demo):
    _, _, summary = demo
    assert summary["truth_samples"] > 90 * summary["duration"]
    assert summary["violations"] == 0
    assert summary["min_margin"] > 0.0


def test_the_run_lasts_the_scenario_and_nothing_stops_the_robot(demo):
    scenario, _, summary = demo
    assert summary["duration"] == pytest.approx(RUNS[scenario], abs=0.1)
    assert summary["estops"] == 0, summary["event_log"]
    assert summary["steps"] > 40 * RUNS[scenario]          # RobotState at 50 Hz


def test_the_console_that_ends_hands_control_back_at_once(demo):
    """At the run's end the console, stopped, releases its lease: the controller reports it released
    (not expired a second later) within half a second of the end, and nothing else took it meanwhile."""
    scenario, _, summary = demo
    ends = [e for e in summary["event_log"] if e["kind"] == "lease_change" and e["t"] > 1.0]
    assert ends and "lease released" in ends[0]["text"], ends
    assert RUNS[scenario] - 0.1 < ends[0]["t"] < RUNS[scenario] + 0.5, ends


def test_the_distributed_run_matches_the_sampled_simulation_of_the_same_plant(demo):
    _, _, summary = demo
    dev = summary["deviation_plant"]
    assert dev["final_pose_distance"] <= TOLERANCE["final_pose_distance"], dev
    assert dev["human_authority_difference"] <= TOLERANCE["human_authority_difference"], dev


def test_the_in_process_references_are_safe_too(demo):
    _, _, summary = demo
    assert summary["reference"]["violations"] == 0 and summary["reference_plant"]["violations"] == 0


def test_every_process_exits_cleanly_within_2_s_of_sigterm(demo):
    _, _, summary = demo
    assert list(summary["processes"]) == ["console", "controller", "robot"]
    for name, proc in summary["processes"].items():
        assert proc["exit_code"] == 0 and not proc["killed"], (name, proc)
        assert proc["stop_seconds"] < 2.0, (name, proc)


def test_the_demos_json_holds_the_robots_and_the_controllers_exit_summaries(demo):
    """Both real-time loops ran the whole scenario: the robot's physics at 1 kHz and the controller's ticks at
    500 Hz (each deadline ticked or skipped), as their `--json` summaries say."""
    scenario, _, summary = demo
    robot, controller = summary["processes"]["robot"]["summary"], summary["processes"]["controller"]["summary"]
    assert robot["physics_steps"] * 1e-3 + robot["skipped_s"] == pytest.approx(robot["elapsed_s"], abs=1e-6)
    assert robot["elapsed_s"] > RUNS[scenario] and controller["elapsed_s"] > RUNS[scenario]
    deadlines = 500.0 * controller["elapsed_s"]
    assert abs(controller["ticks"] + controller["missed"] - deadlines) < 0.05 * deadlines
    assert summary["processes"]["console"]["summary"] is None          # the console writes none


def test_no_process_is_left_behind(demo):
    _, _, summary = demo
    assert not [name for name, proc in summary["processes"].items() if alive(proc["pid"])]


def test_sigterm_to_the_demo_stops_every_child_and_leaves_none(tmp_path):
    out = tmp_path / "demo.json"
    demo = subprocess.Popen(
        [sys.executable, "-m", "sharedctl.services.cli", "demo", "--headless", "--no-reference", "--duration", "60",
         *FEEDBACK_TIMEOUT, "--json", str(out), "--log-dir", str(tmp_path / "logs")],
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        time.sleep(8.0)                         # started, the operator driving
        demo.send_signal(signal.SIGTERM)
        demo.wait(timeout=15)
    finally:
        if demo.poll() is None:
            demo.kill()
            demo.wait()
    summary = json.loads(out.read_text())
    assert summary["interrupted"]
    assert summary["duration"] < 10.0
    for name, proc in summary["processes"].items():
        assert proc["exit_code"] == 0 and proc["stop_seconds"] < 2.0 and not proc["killed"], (name, proc)
        assert not alive(proc["pid"]), name
