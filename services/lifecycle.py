"""Process lifecycle: a stop flag set by SIGINT/SIGTERM, and a fixed-rate loop clock."""
from __future__ import annotations

import signal
import threading
import time


_WALL0, _MONO0 = time.time(), time.monotonic()


def steady_wall() -> float:
    """Wall-clock seconds that never step: the wall clock read once, at import, carried forward on the
    monotonic clock (which NTP slews but never steps). For the times a process sends (an operator
    command's `send_time`): a host's clock stepped by 0.5–2 s must not make its messages look stale or
    early to their receiver (services/controller/replay_guard.py)."""
    return _WALL0 + (time.monotonic() - _MONO0)


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


def poll_until(t: float) -> None:
    """Return at monotonic time `t` (at once if it has passed), polling the clock all the way: never
    sleeping. A thread that sleeps gives up its CPU, and on a virtual machine an idle vCPU is
    descheduled: on an overloaded host it can wake milliseconds late. For a hold between
    computing an actuator command and sending it, that lateness would be actuation delay; polled,
    the hold ends at `t` unless the host takes the CPU away from a running thread, which delays a
    send made at once just as much. Costs the CPU time of the hold (meant for a thread alone on its
    CPU: the controller's loop, `--cpu`)."""
    while time.monotonic() < t:
        pass


class Schedule:
    """A cyclic send time on any clock: `due(now)` is True once per period, never in bursts after a stall
    (a send reached late keeps the next on the period's grid; after a stall of a period or more, the next
    is a period after now). The robot's cyclic frames and truth messages, the controller's telemetry."""

    def __init__(self, rate_hz: float, start: float = 0.0) -> None:
        self.period = 1.0 / rate_hz
        self.next = start

    def due(self, now: float) -> bool:
        if now + 1e-9 < self.next:
            return False
        self.next += self.period
        if self.next <= now:
            self.next = now + self.period
        return True


class RateClock:
    """Absolute-deadline periodic clock (no drift): `wait()` sleeps until the next tick.

    Returns the lateness of the tick in seconds; counts ticks that were missed entirely.

    `spin` (s, default 0): sleep only until `spin` before the deadline and poll the clock for the
    rest. A sleeping thread wakes some tens of microseconds after its timer (more on a virtual
    machine); polling the last stretch starts the tick on time, at the cost of at most `spin` of
    CPU per tick (the sleep never returns early). Meant for a real-time loop thread with a short
    period (the controller: 100 µs at 500 Hz, ≤ 5 % of a core); 0 keeps the plain sleep.
    """

    def __init__(self, period: float, spin: float = 0.0) -> None:
        if spin < 0.0:
            raise ValueError(f"spin must be ≥ 0, got {spin}")
        self.period = period
        self.spin = min(spin, period)
        self.start = time.monotonic()
        self.next = self.start + period
        self.missed = 0

    def wait(self) -> float:
        now = time.monotonic()
        if now > self.next + self.period:
            skipped = int((now - self.next) / self.period)
            self.missed += skipped
            self.next += skipped * self.period
        delay = self.next - now - self.spin
        if delay > 0:
            time.sleep(delay)
        if self.spin > 0.0:
            deadline = self.next
            while time.monotonic() < deadline:
                pass
        lateness = max(0.0, time.monotonic() - self.next)
        self.next += self.period
        return lateness

    def elapsed(self) -> float:
        return time.monotonic() - self.start
