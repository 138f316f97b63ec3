"""Recorder threads yield to the control loop: they run at nice ≥ 0 even inside a process raised to nice −10."""
from __future__ import annotations

import os
import threading

RECORDER_NICE = 0


def lower_this_thread(nice: int = RECORDER_NICE) -> None:
    """Raise the calling thread's nice value to at least ``nice`` (Linux: per thread; always permitted)."""
    try:
        tid = threading.get_native_id()
        if os.getpriority(os.PRIO_PROCESS, tid) < nice:
            os.setpriority(os.PRIO_PROCESS, tid, nice)
    except (AttributeError, OSError):
        pass
