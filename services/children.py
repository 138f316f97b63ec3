"""Child processes of a launcher: start with a log file, stop with SIGTERM then (only if needed)
SIGKILL, know whether they exited cleanly. Only processes this module started are ever signalled."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from .controller.priority import session_nice

STOP_TIMEOUT = 2.0        # s a child gets to exit after SIGTERM


@dataclass
class Child:
    """One process this demo started (and the only kind it will ever signal)."""

    name: str
    popen: subprocess.Popen
    log: Path | None
    exit_code: int | None = None
    stop_seconds: float | None = None
    killed: bool = False

    def stop(self, timeout: float = STOP_TIMEOUT) -> None:
        """SIGTERM, wait up to `timeout`, SIGKILL as a last resort; records how it ended."""
        start = time.monotonic()
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)
            try:
                self.popen.wait(timeout)
            except subprocess.TimeoutExpired:
                self.killed = True
                self.popen.kill()
                self.popen.wait()
        self.stop_seconds = time.monotonic() - start
        self.exit_code = self.popen.returncode

    @property
    def clean(self) -> bool:
        return self.exit_code == 0 and not self.killed

    def report(self) -> dict:
        return {"pid": self.popen.pid, "exit_code": self.exit_code, "stop_seconds": self.stop_seconds,
                "killed": self.killed}

    def tail(self, lines: int = 12) -> str:
        if self.log is None or not self.log.exists():
            return ""
        return "\n".join(self.log.read_text(errors="replace").splitlines()[-lines:])


def python_module(module: str) -> list[str]:
    """The command line that runs `module` of the *installed* package with this interpreter.

    `-P` (Python 3.11): `-m` would otherwise put the working directory first on the import path, and
    from a source tree (or the image's WORKDIR, which holds copies of the source folders) the
    folder `sharedctl/`, which has no `services/`, would hide the installed package."""
    return [sys.executable, "-P", "-m", module]


def start_child(name: str, argv: list[str], log_dir: Path, interactive: bool = False) -> Child:
    """`python -P -m sharedctl.services.cli ARGV` in its own session (a terminal's Ctrl-C reaches only the demo)."""
    cmd = [*python_module("sharedctl.services.cli"), *argv]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    if interactive:
        popen = subprocess.Popen(cmd, env=env, start_new_session=True)
        return Child(name, popen, None)
    log = log_dir / f"{name}.log"
    with open(log, "wb") as out:
        popen = subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                 start_new_session=True)
    return Child(name, popen, log)


def udp_receive_buffer_errors() -> int | None:
    """Host-wide count of UDP datagrams dropped on a full receive buffer (Linux /proc/net/snmp), or None.

    CAN on udp_multicast loses frames this way when a reader falls behind: lost torque frames
    trip the drives' watchdogs, lost encoder frames the controller's feedback timeout."""
    try:
        lines = [line.split() for line in Path("/proc/net/snmp").read_text().splitlines() if line.startswith("Udp:")]
        return int(lines[1][lines[0].index("RcvbufErrors")])
    except (OSError, IndexError, ValueError):
        return None


def raise_priority(pid: int, nice: int = -10) -> str:
    """Give the simulated robot (the plant) the controller's default priority, nice −10, if allowed: the
    process's, and its session's autogroup's (each child leads a session of its own; see
    services/controller/priority.py on autogroups).

    Set right after the start, before the child creates threads (they inherit it)."""
    try:
        os.setpriority(os.PRIO_PROCESS, pid, nice)
    except (PermissionError, OSError):
        return "normal"
    return f"nice {nice}" + (" (its session's too)" if session_nice(pid, nice) else "")


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_listening(endpoint: str, child: Child, timeout: float) -> bool:
    """True once `endpoint` (tcp/127.0.0.1:PORT) accepts connections; False if the child died or time ran out."""
    host, _, port = endpoint[4:].rpartition(":")
    host = host.strip("[]")
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if child.popen.poll() is not None:
            return False
        try:
            with socket.create_connection((host, int(port)), timeout=0.2):
                return True
        except OSError:
            time.sleep(0.05)
    return False
