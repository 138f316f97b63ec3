"""The quick fault campaign, for real: `sharedctl faults campaign --quick` runs 20 demos with faults
(operator, telemetry and CAN impairments, controller kill and hang, console and robot kill) and
every ground-truth violation must be one docs/safety.md documents (a loss of actuation at speed,
or a torque-loop delay beyond the measured limit)."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = [pytest.mark.processes, pytest.mark.campaign]


def test_quick_campaign_has_no_violation_outside_the_documented_limits(tmp_path):
    out = tmp_path / "campaign.json"
    proc = subprocess.Popen([sys.executable, "-m", "sharedctl.services.cli", "faults", "campaign", "--quick",
                             "--json", str(out), "--report", str(tmp_path / "report")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        _, err = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.terminate()
            proc.communicate(timeout=30)
    result = json.loads(out.read_text())
    rows = result["rows"]
    assert result["runs"] >= 20 and len(rows) == result["runs"], err.decode(errors="replace")[-2000:]
    assert result["errors"] == [], [r["error"] for r in rows if r["outcome"] == "error"]
    assert result["unexpected_violations"] == [], result["unexpected_violations"]
    for row in rows:
        assert row["truth_samples"] > 0
        if row["faults"]:
            assert row["injected"], f"{row['id']}: the demo reports nothing injected"
    process_faults = [p for r in rows if r["injected"] for p in r["injected"].get("processes", [])]
    assert len(process_faults) >= 6 and all(p["done_at"] is not None or p["skipped"] for p in process_faults)
    assert (tmp_path / "report" / "README.md").exists()
