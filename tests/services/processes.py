"""Helpers the multi-process tests share: reaping what a test started, and polling."""
from __future__ import annotations

import subprocess
import time


def reap(procs) -> None:
    """Terminate, then (only if it will not stop) kill, each process of `procs` still running."""
    for proc in procs:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=3)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=3)


#: s a launcher (`sharedctl demo`) gets after SIGTERM to stop its children in order, each ≤ 2 s, and exit
LAUNCHER_STOP = 30.0


def run_launcher(argv, timeout: float, capture_output: bool = False, **popen) -> subprocess.CompletedProcess:
    """`subprocess.run(argv, timeout=…, **popen)` for a process that starts children of its own in their own
    sessions (the demo): on a timeout, or when the test itself is interrupted, the launcher gets SIGTERM, so
    that it stops its children as it does at its end, and SIGKILL only if it has not exited after
    `LAUNCHER_STOP` — where `subprocess.run` would kill it at once and leave its children running."""
    if capture_output:
        popen.update(stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    with subprocess.Popen(argv, **popen) as proc:
        try:
            out, err = proc.communicate(timeout=timeout)
        except BaseException:                     # TimeoutExpired, KeyboardInterrupt, …: stop it, then re-raise
            proc.terminate()
            try:
                proc.communicate(timeout=LAUNCHER_STOP)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.communicate()
            raise
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def wait_for(predicate, timeout: float, what: str, poll: float = 0.01) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(poll)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")
