"""Scheduling priority for the control loop (a 500 Hz loop must not wait behind batch jobs).

`high` lowers the process's nice value to −10 (inherited by threads created afterwards: call it
before opening Zenoh and CAN); `realtime` additionally puts the calling thread (the control
loop) in SCHED_FIFO at priority 20. The loop sleeps most of each period, and the kernel's RT
throttling (sched_rt_runtime_us) still bounds an RT thread that would not. Both fall back
quietly when the process may not raise its priority; the result is reported.
"""
from __future__ import annotations

import os

LEVELS = ("normal", "high", "realtime")
NICE = -10
FIFO_PRIORITY = 20


def raise_priority(level: str) -> str:
    """Apply `level`; return what was obtained (e.g. "nice -10", "SCHED_FIFO 20", "normal")."""
    if level not in LEVELS:
        raise ValueError(f"priority must be one of {LEVELS}, got {level!r}")
    obtained = "normal"
    if level in ("high", "realtime"):
        try:
            current = os.nice(0)
            if current > NICE:
                os.nice(NICE - current)
            obtained = f"nice {os.nice(0)}"
        except (OSError, AttributeError):
            pass
    if level == "realtime":
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(FIFO_PRIORITY))
            obtained = f"SCHED_FIFO {FIFO_PRIORITY}"
        except (OSError, AttributeError):
            pass
    return obtained
