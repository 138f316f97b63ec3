"""Process lifecycle: a stop flag set by SIGINT/SIGTERM, and a fixed-rate loop clock."""
from __future__ import annotations

import signal
import threading
import time


class StopFlag:
    """Set by SIGINT or SIGTERM (install() in the main thread) or by stop()."""

    def __init__(self) -> None:
        self._event = threading.Event()

    def install(self) -> "StopFlag":
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: self._event.set())
        return self

    def stop(self) -> None:
        self._event.set()

    @property
    def stopped(self) -> bool:
        return self._event.is_set()

    def wait(self, seconds: float) -> bool:
        return self._event.wait(seconds)


class RateClock:
    """Absolute-deadline periodic clock (no drift): `wait()` sleeps until the next tick.

    Returns the lateness of the tick in seconds; counts ticks that were missed entirely.
    """

    def __init__(self, period: float) -> None:
        self.period = period
        self.start = time.monotonic()
        self.next = self.start + period
        self.missed = 0

    def wait(self) -> float:
        now = time.monotonic()
        if now > self.next + self.period:
            skipped = int((now - self.next) / self.period)
            self.missed += skipped
            self.next += skipped * self.period
        delay = self.next - now
        if delay > 0:
            time.sleep(delay)
        lateness = max(0.0, time.monotonic() - self.next)
        self.next += self.period
        return lateness

    def elapsed(self) -> float:
        return time.monotonic() - self.start
