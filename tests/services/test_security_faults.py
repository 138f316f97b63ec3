"""`sharedctl demo --secure --fault …`: the secured stack meets faults (docs/security.md). Before, the two could not
be combined. One run of the adversarial wall behind the router: the router killed and started again, the
controller killed and restarted (it resumes disarmed), an operator's estop sent with the operator role's
credentials, and another CAN master — and the ground truth stays inside the set."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = [pytest.mark.processes, pytest.mark.slow]

FAULTS = ("router.restart_at=0.5,0.5", "controller.kill_at=1.5", "controller.restart_at=2.5",
          "operator.estop_at=3.5")


def test_the_secured_stack_meets_a_router_restart_a_controller_restart_and_an_estop(tmp_path):
    out = tmp_path / "demo.json"
    argv = [sys.executable, "-m", "sharedctl.services.cli", "demo", "--secure", "--headless", "--no-reference",
            "--scenario", "adversarial_wall", "--duration", "4.5", "--json", str(out), "--log-dir", str(tmp_path / "l"),
            "--feedback-timeout-ms", "150"]
    for spec in FAULTS:
        argv += ["--fault", spec]
    proc = subprocess.run(argv, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=180)
    summary = json.loads(out.read_text())
    assert summary["failure"] is None and summary["violations"] == 0, proc.stderr
    fired = {p["fault"]: p for p in summary["injected"]["processes"]}
    assert all(fired[f]["done_at"] is not None and fired[f]["skipped"] is None for f in FAULTS), fired
    assert summary["injected"]["intrusions"]["bounce"]["back_listening"] is True
    restarted = summary["processes"]["controller"]["summary"]
    assert restarted["start"].startswith("resumed from a checkpoint") and restarted["mode"] == "estopped"
    assert summary["security"]["credentials_removed"] is True
