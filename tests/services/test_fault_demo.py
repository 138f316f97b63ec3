"""`sharedctl demo --fault …`: an operator fault and a controller kill wired into a real run
(the CAN gateway has its own test: with it, this run adds a fourth busy process to the host); the JSON
shows what was injected, and the run is judged as services/faults/stack.py says
(0 ground-truth violations, every process not killed on purpose exits cleanly)."""
import json
import sys
from pathlib import Path

import pytest

from .processes import run_launcher

pytestmark = pytest.mark.processes

FAULTS = ["operator.loss=0.3", "operator.delay_ms=200", "controller.kill_at=2"]


def test_demo_with_faults_reports_what_was_injected(tmp_path):
    out = tmp_path / "demo.json"
    argv = [sys.executable, "-m", "sharedctl.services.cli", "demo", "--headless", "--duration", "4", "--no-reference",
            "--feedback-timeout-ms", "150", "--json", str(out), "--log-dir", str(tmp_path / "logs"),
            "--fault-seed", "1"]
    for spec in FAULTS:
        argv += ["--fault", spec]
    proc = run_launcher(argv, capture_output=True, timeout=120)
    summary = json.loads(out.read_text())
    assert summary["faults"] == FAULTS
    assert (summary["injected"]["not_ok"] == [] and summary["ok"] is True
            and proc.returncode == 0), proc.stderr.decode()[-2000:]
    assert summary["violations"] == 0 and summary["truth_samples"] > 0

    injected = summary["injected"]
    operator = injected["relay"]["operator"]
    assert operator["received"] > 50 and abs(operator["measured_drop_rate"] - 0.3) < 0.15
    assert operator["latency_ms_mean"] >= 200
    assert injected["relay"]["telemetry"]["stages"] == [] and injected["relay"]["exit_code"] == 0
    assert "gateway" not in injected          # no can.* fault: controller and robot share one bus
    kill, = injected["processes"]
    assert kill["action"] == "kill" and 2.0 <= kill["done_at"] < 3.0
    assert injected["killed"][0]["exit_code"] == -9
    for name in ("console", "robot"):
        assert summary["processes"][name]["exit_code"] == 0
    # the robot's exit summary is in the demo's JSON; the controller, killed, wrote none
    assert summary["processes"]["robot"]["summary"]["physics_steps"] > 0
    assert summary["processes"]["controller"]["summary"] is None
    for pid in [kill["pid"], *(p["pid"] for p in summary["processes"].values())]:
        assert not Path(f"/proc/{pid}").exists() or b"sharedctl" not in Path(f"/proc/{pid}/cmdline").read_bytes()


def test_demo_refuses_a_bad_fault_spec():
    proc = run_launcher([sys.executable, "-m", "sharedctl.services.cli", "demo", "--headless",
                         "--fault", "operator.loss=2"], capture_output=True, timeout=60)
    assert proc.returncode == 2 and b"operator.loss=2" in proc.stderr


def test_a_timed_fault_fires_at_its_time_after_the_lease_on_the_controllers_own_clock(tmp_path):
    """An operator's estop at 1.2 s: the controller's own estop event, on its own clock less the lease
    instant it reports, lands within one control period plus the stack's scheduling tolerance of 1.2 s
    (the demo learns t = 0 one telemetry period or more after it); the JSON keeps the ground truth
    around the instant for the campaign's forecast."""
    from sharedctl.services.faults.stack import SCHEDULING_TOLERANCE

    period = 0.002
    out = tmp_path / "demo.json"
    argv = [sys.executable, "-m", "sharedctl.services.cli", "demo", "--scenario", "adversarial_wall", "--headless",
            "--duration", "2", "--no-reference", "--json", str(out), "--log-dir", str(tmp_path / "logs"),
            "--fault", "operator.estop_at=1.2"]
    proc = run_launcher(argv, capture_output=True, timeout=120)
    summary = json.loads(out.read_text())
    assert summary["run_clock"] == "lease", proc.stderr.decode()[-2000:]
    fired, = summary["injected"]["processes"]
    assert 0.0 <= fired["done_at"] - 1.2 <= SCHEDULING_TOLERANCE
    estop = next(e for e in summary["event_log"] if e["kind"] == "estop")
    assert 1.2 <= estop["at"] <= 1.2 + period + SCHEDULING_TOLERANCE
    state = next(s for s in summary["fault_states"] if s["what"] == "operator.estop_at=1.2")
    times = [row[0] for row in state["truth"]]
    assert min(times) < fired["done_at"] < max(times) and state["torques"]
