"""`sharedctl demo --secure --fault …`: the secured stack meets faults (docs/security.md). Before, the two could not
be combined. One run of the adversarial wall behind the router: the router killed and started again, the
controller killed and restarted (it resumes disarmed), an operator's estop pressed 50 ms after the restart and held,
sent with the operator role's credentials, and another CAN master — and the ground truth stays inside the set. The
restarted controller is still starting when the estop is pressed; sent once, the estop was lost and it ended `held`."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from .processes import run_launcher

pytestmark = [pytest.mark.processes, pytest.mark.slow]

FAULTS = ("router.restart_at=0.5,0.5", "controller.kill_at=1.5", "controller.restart_at=2.5",
          "operator.estop_at=2.55")


def test_the_secured_stack_meets_a_router_restart_a_controller_restart_and_an_estop(tmp_path):
    out = tmp_path / "demo.json"
    argv = [sys.executable, "-m", "sharedctl.services.cli", "demo", "--secure", "--headless", "--no-reference",
            "--scenario", "adversarial_wall", "--duration", "4.5", "--json", str(out), "--log-dir", str(tmp_path / "l"),
            "--feedback-timeout-ms", "150"]
    for spec in FAULTS:
        argv += ["--fault", spec]
    proc = run_launcher(argv, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=180)
    summary = json.loads(out.read_text())
    assert summary["failure"] is None and summary["violations"] == 0, proc.stderr
    fired = {p["fault"]: p for p in summary["injected"]["processes"]}
    assert all(fired[f]["done_at"] is not None and fired[f]["skipped"] is None for f in FAULTS), fired
    assert fired[FAULTS[-1]]["sent"] > 1                              # the button stayed held
    assert summary["injected"]["intrusions"]["bounce"]["back_listening"] is True
    restarted = summary["processes"]["controller"]["summary"]
    assert restarted["start"].startswith("resumed from a checkpoint") and restarted["mode"] == "estopped"
    assert summary["security"]["credentials_removed"] is True


def test_behind_the_router_unsigned_floods_and_a_replayed_signed_command_move_nothing(tmp_path):
    """The operator credential at the router is not enough: commands must be signed by an operator the controller
    trusts. A flood and 200 junk sessions sent with the router credential but no operator key are refused as
    `unsigned` before any session state is touched; the holder's captured signed command, replayed, is a duplicate.
    The console (signing) keeps control throughout."""
    out = tmp_path / "demo.json"
    argv = [sys.executable, "-m", "sharedctl.services.cli", "demo", "--secure", "--headless", "--no-reference",
            "--scenario", "adversarial_wall", "--duration", "3.5", "--json", str(out), "--log-dir", str(tmp_path / "l"),
            "--feedback-timeout-ms", "150", "--fault", "operator.flood_at=1,500,1", "--fault", "operator.evict_at=2.5"]
    proc = run_launcher(argv, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=180)
    summary = json.loads(out.read_text())
    assert summary["failure"] is None and summary["violations"] == 0, proc.stderr
    flood, evict = (summary["injected"]["intrusions"][k] for k in ("flood", "evict"))
    assert evict["replayed"] is True
    rejections = summary["processes"]["controller"]["summary"]["rejections"]
    # on the code before operator identity, the flood's sessions were judged as operators (not_holder, rate_limited)
    assert rejections.get("unsigned", 0) == flood["commands"] + evict["sessions"], rejections
    assert rejections.get("duplicate_seq", 0) + rejections.get("out_of_order_seq", 0) >= 1, rejections
    assert not {"not_holder", "rate_limited", "identity_mismatch", "bad_signature"} & set(rejections), rejections
    assert summary["estops"] == 0
    controller = summary["processes"]["controller"]["summary"]
    assert controller["commands_accepted"] >= 0.7 * 50 * 3.5      # the console drove, signed, all along (50 Hz)


def test_link_faults_behind_the_routers_reach_the_controller_with_every_message_accounted_for(tmp_path):
    """Before, `--secure` refused the operator.*/telemetry.* faults (their relay was a plain peer). Now the console has
    a router of its own and the relay is a client of both, so the impairments run against the secured stack: every
    command the relay delivered was either accepted or refused for a reason, the signatures passed the relay (nothing
    `unsigned`), a corrupted command is refused on its signature before it is decoded, a replayed or duplicated one
    (validly signed) by the replay guard."""
    out = tmp_path / "demo.json"
    argv = [sys.executable, "-m", "sharedctl.services.cli", "demo", "--secure", "--headless", "--no-reference",
            "--scenario", "adversarial_wall", "--duration", "3", "--json", str(out), "--log-dir", str(tmp_path / "l"),
            "--feedback-timeout-ms", "150", "--fault", "operator.corrupt=0.2", "--fault", "operator.replay=0.2,300",
            "--fault", "operator.duplicate=0.2", "--fault", "telemetry.delay_ms=30", "--fault", "telemetry.loss=0.1"]
    proc = run_launcher(argv, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=180)
    summary = json.loads(out.read_text())
    assert summary["failure"] is None and summary["violations"] == 0, proc.stderr
    assert summary["security"]["console_router"]["exit_code"] == 0
    relay = summary["injected"]["relay"]
    assert relay["through_routers"] == {"console": True, "controller": True}
    operator, telemetry = relay["operator"], relay["telemetry"]
    assert operator["corrupted"] > 0 and operator["replayed"] > 0 and telemetry["lost"] > 0
    controller = summary["processes"]["controller"]["summary"]
    rejections = controller["rejections"]
    assert sum(rejections.values()) + controller["commands_accepted"] == operator["delivered"], rejections
    assert rejections["bad_signature"] >= operator["corrupted"], rejections
    assert set(rejections) <= {"bad_signature", "duplicate_seq", "out_of_order_seq", "stale"}, rejections
    assert controller["commands_accepted"] >= 0.6 * 50 * 3
