"""Plausibility of a wheel's encoder estimate against the previous one: a corrupted value never
reaches the odometry.

CANSimple frames carry no end-to-end check of their own. On a real bus the CAN CRC catches
bit errors, but a faulty node or bridge can still put a well-formed frame with a wrong value on
the bus (the fault campaign's `can.corrupt` does exactly that: one flipped bit in a frame
that still decodes). One wrong position estimate would shift the dead-reckoned pose for good
(the odometry integrates position increments), and a pose error next to a face is a margin the
robot does not have.

Pure: estimates and their arrival times in, the estimate to use and the reason for any
substitution out. The two values of one `Get_Encoder_Estimates` frame check each other and the
previous frame of the same wheel:

* velocity: |v − v_prev| ≤ `max_accel`·Δt + `vel_slack` (the drive cannot accelerate the wheel
  faster than its torque limit allows); otherwise the velocity is held at v_prev;
* position: |Δp − ½(v_prev + v)·Δt| ≤ `pos_slack` + `timing_slack`·|v| (the increment agrees with
  the measured speed over the time between arrivals, with room for arrival-time jitter);
  otherwise the position is replaced by p_prev + ½(v_prev + v)·Δt.

A substituted value is counted by the caller. `rebaseline_after` consecutive position rejections
accept the new position as it is: a drive that restarted from 0 turns is a real discontinuity
(the odometry re-baselines on it and keeps its pose), not a corruption that repeats itself.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .odometry import AxisEstimate


@dataclass(frozen=True)
class EncoderCheck:
    max_accel: float = 600.0        # turns/s²: above the wheels' reach at the 60 N·m torque limit (~500)
    vel_slack: float = 0.5          # turns/s
    pos_slack: float = 0.002        # turns (0.5 mm of wheel travel)
    timing_slack: float = 0.02      # s of arrival-time jitter allowed in the position check (delays, bursts)
    rebaseline_after: int = 5       # consecutive position rejections that make a new baseline

    def judge(self, prev: AxisEstimate | None, pos: float, vel: float, now: float,
              rejected_in_a_row: int = 0) -> tuple[AxisEstimate, str | None]:
        """The estimate to keep for a frame (pos turns, vel turns/s) arriving at `now`, and why a
        value was replaced ("implausible_velocity", "implausible_position") or None."""
        if not (math.isfinite(pos) and math.isfinite(vel)):
            # the codec refuses non-finite values; kept here so the odometry never sees one
            held = prev if prev is not None else AxisEstimate(0.0, 0.0, now)
            return AxisEstimate(held.pos_turns, held.vel_turns_s, now), "implausible_position"
        if prev is None:
            return AxisEstimate(pos, vel, now), None
        dt = max(now - prev.received, 0.0)
        reason = None
        if abs(vel - prev.vel_turns_s) > self.max_accel * dt + self.vel_slack:
            vel, reason = prev.vel_turns_s, "implausible_velocity"
        expected = prev.pos_turns + 0.5 * (prev.vel_turns_s + vel) * dt
        tolerance = self.pos_slack + self.timing_slack * max(abs(vel), abs(prev.vel_turns_s))
        if abs(pos - expected) > tolerance and rejected_in_a_row + 1 < self.rebaseline_after:
            pos, reason = expected, "implausible_position"
        return AxisEstimate(pos, vel, now), reason
