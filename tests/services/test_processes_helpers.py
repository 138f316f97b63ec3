"""The process tests' helpers (tests/services/processes.py): a launcher that times out is stopped the way it
stops at its end, so the children it started in their own sessions do not outlive the test."""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from .processes import run_launcher, wait_for

pytestmark = pytest.mark.processes     # starts processes

#: a launcher in miniature: a child in a session of its own, stopped by the launcher on SIGTERM (as `demo` does)
LAUNCHER = """
import signal, subprocess, sys, time
child = subprocess.Popen(["sleep", "60"], start_new_session=True)
open(sys.argv[1], "w").write(str(child.pid))
def stop(*_):
    child.terminate(); child.wait(); sys.exit(0)
signal.signal(signal.SIGTERM, stop)
print("started", flush=True)
time.sleep(60)
"""


def running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except (FileNotFoundError, IndexError):
        return False


def test_a_launcher_that_times_out_stops_its_children_before_the_timeout_is_raised(tmp_path):
    pid_file = tmp_path / "child.pid"
    started = time.monotonic()
    with pytest.raises(subprocess.TimeoutExpired):
        run_launcher([sys.executable, "-c", LAUNCHER, str(pid_file)], timeout=2.0, capture_output=True, text=True)
    child = int(pid_file.read_text())
    assert not running(child), "the launcher's child outlived it"
    assert time.monotonic() - started < 2.0 + 10.0


def test_a_launcher_that_ends_in_time_gives_what_subprocess_run_gives(tmp_path):
    done = run_launcher([sys.executable, "-c", "import sys; print('out'); print('err', file=sys.stderr); sys.exit(3)"],
                        timeout=30.0, capture_output=True, text=True)
    assert (done.returncode, done.stdout, done.stderr) == (3, "out\n", "err\n")


def test_wait_for_names_what_it_waited_for():
    with pytest.raises(AssertionError, match="the impossible"):
        wait_for(lambda: False, 0.05, "the impossible")
