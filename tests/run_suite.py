"""`make test`'s two test phases, at the same time: the tests that start processes or open sockets (marked
`processes`) in the foreground, one at a time, and the pure tests (simulations, codecs) on two workers in the
background, at the lowest priority, so that they take only the CPU the processes leave.

The process tests measure real-time behaviour (a 500 Hz controller, a 1 kHz simulated robot, ms-scale latencies):
whatever runs beside them must yield the CPU to them at once. Lowering the pure tests' nice value alone does not do
it on a kernel with autogroups (`/proc/sys/kernel/sched_autogroup_enabled`): the scheduler then shares the CPU
between sessions first, and the demo's children each run in a session of their own (services/children.py), so a
nice-19 process in another session still weighs as much as any of them. The pure tests therefore start in a session of
their own whose autogroup is set to nice 19 (`background`), and are nice 19 themselves for kernels without
autogroups.

The process tests' output comes as they run, the pure tests' when both are done (from a temporary file); the exit
status is 0 only if both phases passed (else the process tests' status, or the pure tests'). On SIGTERM the runner
sends SIGINT to the process tests (pytest then stops as on Ctrl-C, and its fixtures reap the processes its tests
started) and to the pure tests' session, SIGKILL to either that has not ended within STOP_TIMEOUT, and exits; on
Ctrl-C, which the process tests received too, it waits for them and stops the pure tests the same way.

    python tests/run_suite.py [ARGS...]    # ARGS go to both pytest runs
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time

from sharedctl.services.controller.priority import session_nice

PURE = ["-n", "2", "--dist", "loadfile", "--durations=15", "-m", "not processes"]
PROCESSES = ["--durations=15", "-m", "processes"]
NICE = 19
STOP_TIMEOUT = 30.0   # s a phase gets to stop on SIGINT (its fixtures reap their processes) before SIGKILL


def background() -> None:
    """In the child, after its new session began: the session's autogroup (where the kernel has them) and the
    process at nice 19."""
    session_nice(os.getpid(), NICE)
    os.nice(NICE - os.nice(0))


def main(args: list[str]) -> int:
    pytest = [sys.executable, "-m", "pytest"]
    started: dict[str, subprocess.Popen] = {}
    stopping: dict = {}

    def send(name: str, signum: int) -> None:
        proc = started.get(name)
        if proc is not None:
            try:                # the pure tests: the session this runner started (pytest and its workers)
                os.killpg(proc.pid, signum) if name == "pure" else os.kill(proc.pid, signum)
            except ProcessLookupError:      # already over
                pass

    def stop(signum, _frame):
        if stopping:
            return
        stopping.update(signum=signum, since=time.monotonic())
        if signum == signal.SIGTERM:    # Ctrl-C reached the process tests too (the terminal's foreground group)
            send("processes", signal.SIGINT)
        send("pure", signal.SIGINT)

    def wait(name: str) -> int:
        """The phase's exit status; SIGKILL once it has had STOP_TIMEOUT to stop since the runner was asked to.
        Polls: the signal handler never waits, so it never meets a wait in progress."""
        proc = started[name]
        while proc.poll() is None:
            if "since" in stopping and time.monotonic() > stopping["since"] + STOP_TIMEOUT:
                send(name, signal.SIGKILL)
            time.sleep(0.1)
        return proc.returncode

    # before the children start, so that they start with SIGINT's default action (Python's KeyboardInterrupt)
    # even where this runner inherited it ignored (a background job of a shell)
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    with tempfile.TemporaryFile() as log:
        started["pure"] = subprocess.Popen([*pytest, *PURE, *args], stdin=subprocess.DEVNULL, stdout=log,
                                           stderr=subprocess.STDOUT, start_new_session=True, preexec_fn=background)
        print(f"the pure tests run beside these at nice {NICE} (pid {started['pure'].pid}); their report follows",
              flush=True)
        if not stopping:
            started["processes"] = subprocess.Popen([*pytest, *PROCESSES, *args])
        process_status = wait("processes") if "processes" in started else None
        pure_status = wait("pure")
        log.seek(0)
        sys.stdout.flush()
        sys.stdout.buffer.write(log.read())
        sys.stdout.flush()
    if stopping:
        return 128 + stopping["signum"]
    return process_status or pure_status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
