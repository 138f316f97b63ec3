"""Sensor-synchronous ticks: the loop's phase locked to the arrival of the wheel estimates.

The drives send their encoder estimates on their own clock (500 Hz), the controller ticks on its
own (`RateClock`). Free-running, a tick uses estimates whose age is the phase between the two
clocks — anywhere in [0, T), fixed for a run, so sensor → torque latency is luck of the start-up
(docs/performance.md). `SensorPhaseLock` moves each next deadline a little towards `lead`
seconds after the estimates last arrived, so ticks settle just after fresh data: the age left
is `lead` plus the tick's own computation.

Pure: times in, a correction (s) to add to the next deadline out. Each correction is at most
`max_step`, so the period never changes by more than that from one tick to the next.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass
class SensorPhaseLock:
    period: float                # s, the control period
    # s after the estimates' arrival at which a tick should start (above the drives' send jitter)
    lead: float = 2.5e-4
    gain: float = 0.2            # fraction of the phase error removed per tick
    max_step: float = 5e-5       # s, largest correction per tick

    def correction(self, next_tick: float, sensor_arrival: float) -> float:
        """Seconds to add to `next_tick` (same clock as `sensor_arrival`)."""
        error = (next_tick - (sensor_arrival + self.lead)) % self.period     # [0, T)
        if error > 0.5 * self.period:
            error -= self.period                                             # (−T/2, T/2]
        step = -self.gain * error
        return max(-self.max_step, min(self.max_step, step))


def estimates_arrival(estimates) -> float | None:
    """When the newest complete set of wheel estimates was there: the latest of their arrival times
    (None until every wheel has reported)."""
    if not estimates or any(e is None for e in estimates):
        return None
    return max(e.received for e in estimates)
