"""deploy/systemd/*.service: `systemd-analyze verify` (warnings count as failures) and their commands."""
import shutil
import subprocess
from pathlib import Path

import pytest

from .deploy_files import DEPLOY, DOC, ROOT, UNITS, parse_command, unit_exec_start, unit_keys

pytestmark = pytest.mark.processes     # runs systemd-analyze

INSTALLED = "/opt/sharedctl/venv/bin/sharedctl"
NAMES = {"sharedctl-router.service", "sharedctl-controller.service", "sharedctl-robot.service"}


def test_the_units_are_router_controller_and_robot():
    assert {u.name for u in UNITS} == NAMES


def test_systemd_analyze_verify_accepts_every_unit_without_a_warning(tmp_path):
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("systemd-analyze is not installed on this host")
    local = ROOT / ".venv" / "bin" / "sharedctl"
    if not local.exists():
        pytest.skip("no .venv/bin/sharedctl to stand in for the installed command")
    for unit in UNITS:                   # ExecStart must be executable here: point it at this checkout's venv
        (tmp_path / unit.name).write_text(unit.read_text().replace(INSTALLED, str(local)))
    probe = subprocess.run([analyze, "verify", "--man=no", str(tmp_path / "sharedctl-robot.service")],
                           capture_output=True, text=True, timeout=60)
    if "Failed to" in probe.stderr and "bus" in probe.stderr.lower():
        pytest.skip(f"systemd-analyze cannot run here: {probe.stderr.strip()[:200]}")
    result = subprocess.run([analyze, "verify", "--man=no", *[str(tmp_path / u.name) for u in UNITS]],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0 and result.stderr.strip() == "", result.stderr


def test_verify_does_report_a_bad_key(tmp_path):
    """The check above can fail: a misspelt key is reported."""
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("systemd-analyze is not installed on this host")
    bad = tmp_path / "bad.service"
    bad.write_text((DEPLOY / "systemd" / "sharedctl-robot.service").read_text()
                   .replace(INSTALLED, str(ROOT / ".venv" / "bin" / "sharedctl")).replace("Restart=", "Restrat="))
    result = subprocess.run([analyze, "verify", "--man=no", str(bad)], capture_output=True, text=True, timeout=60)
    assert "Restrat" in result.stderr


@pytest.mark.parametrize("unit,command,settings", [
    ("sharedctl-controller.service", "controller", "controller.toml"),
    ("sharedctl-robot.service", "robot", "robot.toml"),
])
def test_service_units_run_the_command_with_the_documented_settings_file(unit, command, settings):
    argv = unit_exec_start(DEPLOY / "systemd" / unit)
    assert argv[:4] == [INSTALLED, command, "--service-config", f"/etc/sharedctl/{settings}"]
    parse_command([command, "--service-config", str(DEPLOY / "config" / settings)])
    assert f"deploy/config/{settings}" in DOC.read_text()


def test_the_router_unit_runs_the_generated_router_config():
    argv = unit_exec_start(DEPLOY / "systemd" / "sharedctl-router.service")
    assert argv == [INSTALLED, "router", "--config", "/etc/sharedctl/credentials/router.json5"]


def test_every_unit_is_hardened_and_restarts():
    for unit in UNITS:
        keys = unit_keys(unit)
        assert keys["User"] == "sharedctl" and keys["NoNewPrivileges"] == "yes", unit.name
        assert keys["CapabilityBoundingSet"] == "" and keys["ProtectSystem"] == "strict", unit.name
        assert keys["Restart"] in ("on-failure", "always"), unit.name
        assert keys["KillSignal"] == "SIGTERM", unit.name


def test_only_the_controller_may_use_realtime_scheduling():
    for unit in UNITS:
        keys = unit_keys(unit)
        if unit.name == "sharedctl-controller.service":
            assert int(keys["LimitRTPRIO"]) >= 20 and keys["Nice"] == "-10" and "RestrictRealtime" not in keys
        else:
            assert keys["RestrictRealtime"] == "yes" and "LimitRTPRIO" not in keys


def test_controller_and_robot_start_after_the_router():
    for name in ("sharedctl-controller.service", "sharedctl-robot.service"):
        keys = unit_keys(DEPLOY / "systemd" / name)
        assert "sharedctl-router.service" in keys["After"] and "sharedctl-router.service" in keys["Wants"]


def test_installed_paths_match_the_walkthrough():
    doc = DOC.read_text()
    assert "/opt/sharedctl/venv" in doc and Path(INSTALLED).parent.parent.as_posix() == "/opt/sharedctl/venv"


def expand_group(analyze: str, item: str, seen: set[str]) -> set[str]:
    """The system calls of a filter item; `@group`s (which may name other groups) expanded by systemd-analyze."""
    if not item.startswith("@"):
        return {item}
    if item in seen:
        return set()
    seen.add(item)
    listing = subprocess.run([analyze, "syscall-filter", item], capture_output=True, text=True, timeout=60).stdout
    calls = set()
    for line in listing.splitlines():
        entry = line.strip()
        if line.startswith("    ") and entry and not entry.startswith("#"):
            calls |= expand_group(analyze, entry, seen)
    return calls


def allowed_syscalls(analyze: str, unit: Path) -> set[str]:
    """Every system call a unit's SystemCallFilter= allows."""
    seen: set[str] = set()
    return set().union(*(expand_group(analyze, item, seen) for item in unit_keys(unit)["SystemCallFilter"].split()))


def test_the_controllers_syscall_filter_allows_its_priority_calls():
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("systemd-analyze is not installed on this host")
    allowed = allowed_syscalls(analyze, DEPLOY / "systemd" / "sharedctl-controller.service")
    assert {"sched_setscheduler", "setpriority", "getpriority", "socket", "bind"} <= allowed
    assert "reboot" not in allowed and "kexec_load" not in allowed and "init_module" not in allowed


def test_a_filtered_call_fails_with_eperm_instead_of_killing_the_service():
    for unit in UNITS:
        assert unit_keys(unit)["SystemCallErrorNumber"] == "EPERM", unit.name


def test_the_controllers_checkpoint_folder_is_its_writable_state_directory():
    """ProtectSystem=strict makes the system read-only; the unit's StateDirectory (/var/lib/sharedctl) is the
    one folder it writes, and the settings file keeps the checkpoint there."""
    import tomllib
    keys = unit_keys(next(u for u in UNITS if u.name == "sharedctl-controller.service"))
    checkpoint = Path(tomllib.loads((DEPLOY / "config" / "controller.toml").read_text())["checkpoint"])
    assert checkpoint.parent == Path("/var/lib") / keys["StateDirectory"]
    assert "pose" not in tomllib.loads((DEPLOY / "config" / "controller.toml").read_text())
