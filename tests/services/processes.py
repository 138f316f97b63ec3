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


def wait_for(predicate, timeout: float, what: str, poll: float = 0.01) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(poll)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")
