"""Scheduling priority for the control loop (a 500 Hz loop must not wait behind batch jobs).

Two steps, so that only the loop thread runs real-time:
* `raise_nice()` — before Zenoh and CAN start their threads: nice −10 for the process (threads
  created afterwards inherit it);
* `make_loop_realtime()` — in the loop thread, after the session and the bus are open: SCHED_FIFO
  at priority 20 for that thread alone (Zenoh's threads keep the normal policy). The loop sleeps
  most of each period, and the kernel's RT throttling (sched_rt_runtime_us) still bounds an RT
  thread that would not.
Both fall back quietly when the process may not raise its priority; what was obtained is reported.

On a kernel with autogroups (`/proc/sys/kernel/sched_autogroup_enabled`), the scheduler shares the
CPU between sessions first and by nice only within one: a process that leads a session of its own
(every child of `demo` does) weighs, at nice −10, no more than a nice-19 batch job in another
session. `raise_nice` and `raise_priority` (services/children.py) therefore set the nice of the
process's autogroup as well, when it leads its session (`session_nice`). SCHED_FIFO threads are
above every autogroup.

A thread of the process that runs Python code the loop may wait for — the metrics server's
(services/metrics.py), which holds the interpreter lock while it renders a scrape — gets SCHED_FIFO
too, at `HELPER_PRIORITY`, below the loop's (`make_thread_realtime`): at normal priority, another
process could preempt it while it holds the lock, and the loop, woken for its tick, would wait for
as long as the other process runs (milliseconds on a loaded host). Its work is bounded (the metrics
server serves at most five requests a second).

Optionally a CPU of its own for the loop (`--cpu N`), also in two steps:
* `keep_off_cpu(n)` — before Zenoh and CAN start their threads: the process (and so every thread
  created afterwards) may run on every allowed CPU but n;
* `pin_to_cpu(n)` — in the loop thread: that thread runs on CPU n alone.
No thread of its own process then competes with the loop for that CPU, and it finds more of its
caches as it left them (other processes may still run there unless they are placed elsewhere
too: the bench puts the simulated robot on another CPU). On a machine with one allowed CPU
`keep_off_cpu` leaves the affinity as it is.
"""
from __future__ import annotations

import os

LEVELS = ("realtime", "high", "normal")
NICE = -10
FIFO_PRIORITY = 20
HELPER_PRIORITY = 10    # SCHED_FIFO of the threads that hold the interpreter lock the loop needs (module doc)


def raise_nice(level: str) -> str:
    """nice −10 for `high` and `realtime`; returns e.g. "nice -10" or "normal"."""
    if level not in LEVELS:
        raise ValueError(f"priority must be one of {LEVELS}, got {level!r}")
    if level == "normal":
        return "normal"
    try:
        current = os.nice(0)
        if current > NICE:
            os.nice(NICE - current)
        obtained = os.nice(0)
    except (OSError, AttributeError):
        return "normal"
    return f"nice {obtained}" + (" (its session's too)" if session_nice(os.getpid(), obtained) else "")


def session_nice(pid: int, nice: int) -> bool:
    """The autogroup of `pid`'s session at `nice`, if `pid` leads its session and the kernel has autogroups
    (module doc); False where it does not, or may not (lowering an autogroup's nice needs CAP_SYS_NICE)."""
    try:
        if os.getsid(pid) != pid:
            return False           # a session another process leads: its group is not this process's to set
        with open(f"/proc/{pid}/autogroup", "w") as group:
            group.write(str(nice))
        return True
    except OSError:                # no such file (no autogroups), not permitted, or the process is gone
        return False


def make_loop_realtime() -> bool:
    """SCHED_FIFO for the calling thread; False if not permitted."""
    return make_thread_realtime(FIFO_PRIORITY)


def make_thread_realtime(priority: int = HELPER_PRIORITY) -> bool:
    """SCHED_FIFO at `priority` for the calling thread; False if not permitted."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return True
    except (OSError, AttributeError):
        return False


def keep_off_cpu(cpu: int) -> str:
    """The calling process's threads (and those it creates later) off `cpu`, if another CPU is allowed."""
    try:
        allowed = os.sched_getaffinity(0)
        if cpu not in allowed:
            raise ValueError(f"CPU {cpu} is not among the CPUs this process may use: {sorted(allowed)}")
        others = allowed - {cpu}
        if not others:
            return f"CPU {cpu} is the only one allowed: shared"
        os.sched_setaffinity(0, others)
        return f"other threads on CPUs {','.join(map(str, sorted(others)))}"
    except (OSError, AttributeError) as exc:
        return f"affinity unchanged ({type(exc).__name__})"


def pin_to_cpu(cpu: int) -> bool:
    """The calling thread on `cpu` alone; False if not permitted or not available."""
    try:
        os.sched_setaffinity(0, {cpu})
        return True
    except (OSError, AttributeError, ValueError):
        return False
