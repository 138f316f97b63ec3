"""`make test`'s runner (tests/run_suite.py) starts the pure tests in the background: in a session of their own,
nice 19, and — on a kernel with autogroups — that session's autogroup at nice 19 too, so that they weigh least
beside the process tests' children (each in a session of its own)."""
from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.processes     # starts a process

PROBE = ("import os; print(os.nice(0)); print(os.getsid(0) == os.getpid()); "
         "print(open('/proc/self/autogroup').read().strip() if os.path.exists('/proc/self/autogroup') else '')")


def _runner():
    spec = importlib.util.spec_from_file_location("run_suite", Path(__file__).with_name("run_suite.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _autogroups() -> bool:
    try:
        return Path("/proc/sys/kernel/sched_autogroup_enabled").read_text().strip() == "1"
    except OSError:
        return False


def test_the_background_phase_runs_at_nice_19_in_a_session_whose_autogroup_is_nice_19():
    runner = _runner()
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=30,
                         start_new_session=True, preexec_fn=runner.background, check=True).stdout.splitlines()
    nice, own_session, group = out[0], out[1], out[2] if len(out) > 2 else ""
    assert (int(nice), own_session) == (runner.NICE, "True")
    if _autogroups() and group:
        assert group.endswith(f"nice {runner.NICE}"), group
    mine = Path("/proc/self/autogroup")
    if mine.exists():          # this process's own autogroup is untouched
        assert mine.read_text().strip() != group
