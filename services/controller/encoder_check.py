"""Plausibility of a wheel's encoder estimate against the previous one: a corrupted value never
reaches the odometry.

CANSimple frames carry no end-to-end check of their own. On a real bus the CAN CRC catches
bit errors, but a faulty node or bridge can still put a well-formed frame with a wrong value on
the bus (the fault campaign's `can.corrupt` does exactly that: one flipped bit in a frame
that still decodes). One wrong position estimate would shift the dead-reckoned pose for good
(the odometry integrates position increments), and a pose error next to a face is a margin the
robot does not have.

Pure: estimates and their arrival times in, the estimate to use and the reason for any
rejection out. The two values of one `Get_Encoder_Estimates` frame check each other and the
previous frame of the same wheel. The drives sample on a `period` tick (1 ms) and send every
other tick; how many ticks lie between two received frames is not known (frames get lost, a
delayed link releases several at once, arrival times say little about sampling times), so the
check asks whether *some* whole number of periods k = 1 … `max_periods` (more after a longer gap
between the two frames' arrivals: a stalled host) explains the frame:

* position: |Δp − ½(v_prev + v)·k·period| ≤ `pos_slack` + `speed_slack`·|v| + ½|v − v_prev|·k·period
  for some k (the increment agrees with the measured speeds over whole sampling ticks; the last
  term bounds the trapezoid's error for a speed that changes monotonically).
* velocity (first): |v − v_prev| ≤ `max_accel`·k·period + `vel_slack`, k from the arrival time
  (at least 2) — the drive cannot accelerate the wheel faster than its torque limit allows.

A frame that fails is **dropped**, as if it had been lost: the wheel's previous estimate stands
and the next good frame carries the whole increment (the odometry integrates increments). A
check that instead *replaced* the value by a speed-integrated one was measured to make things
worse: under CAN delay its false alarms injected errors and three runs of the fault campaign
ran away (−0.05 to −0.69 m); dropping a good frame costs no more than a lost one.

At rest and at the low speeds near a face every candidate increment is close to 0, so a wrong
position of more than a few hundredths of a turn is caught where the margin is thin; at speed,
an error that lands on another whole number of periods can pass (the odometry integrates
increments, so the next good frame undoes it).

A dropped frame is counted by the caller. `rebaseline_after` consecutive rejections
accept the new frame as it is, with the next `epoch`: a drive that restarted from 0 turns is a
real discontinuity, not a corruption that repeats itself, and the odometry takes the wheel's
travel over it from its speeds (odometry.py), never from the jump.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .odometry import AxisEstimate


@dataclass(frozen=True)
class EncoderCheck:
    period: float = 0.001           # s: the drive samples on a 1 kHz tick (frames every 2 ticks, ± a tick)
    max_periods: int = 50           # ticks the check considers beyond the arrival gap (50 ms: the feedback timeout)
    max_accel: float = 600.0        # turns/s²: above the wheels' reach at the 60 N·m torque limit (~500)
    vel_slack: float = 0.5          # turns/s
    pos_slack: float = 0.002        # turns (0.5 mm of wheel travel)
    speed_slack: float = 0.0005     # s: tolerance proportional to speed (rounding of the sampling instants)
    rebaseline_after: int = 5       # consecutive position rejections that make a new baseline

    def judge(self, prev: AxisEstimate | None, pos: float, vel: float, now: float,
              rejected_in_a_row: int = 0) -> tuple[AxisEstimate, str | None]:
        """The estimate to keep for a frame (pos turns, vel turns/s) arriving at `now`, and why a
        frame was dropped ("implausible_velocity", "implausible_position") or None."""
        if not (math.isfinite(pos) and math.isfinite(vel)):
            # the codec refuses non-finite values; kept here so the odometry never sees one
            held = prev if prev is not None else AxisEstimate(0.0, 0.0, now)
            return AxisEstimate(held.pos_turns, held.vel_turns_s, now, held.epoch), "implausible_position"
        if prev is None:
            return AxisEstimate(pos, vel, now), None
        epoch = prev.epoch
        v_prev, p_prev = prev.vel_turns_s, prev.pos_turns
        gap = max(round((now - prev.received) / self.period), 0)
        arrived = min(max(gap, 1), self.max_periods)
        reason = None
        if abs(vel - v_prev) > self.max_accel * max(arrived, 2) * self.period + self.vel_slack:
            reason = "implausible_velocity"
        else:
            tolerance = self.pos_slack + self.speed_slack * max(abs(vel), abs(v_prev))
            if self._periods(pos - p_prev, v_prev, vel, tolerance, self.max_periods + gap) is None:
                reason = "implausible_position"
        if reason is not None:
            if rejected_in_a_row + 1 < self.rebaseline_after:
                return prev, reason      # dropped: the wheel's previous estimate stands, as for a lost frame
            epoch += 1                   # a jump that persists: a new origin
        return AxisEstimate(pos, vel, now, epoch), None

    def _periods(self, increment: float, v_prev: float, vel: float, tolerance: float, limit: int) -> int | None:
        """The k in 1 … `limit` whose trapezoid ½(v_prev + v)·k·period is nearest `increment`, if
        within `tolerance` + ½|v − v_prev|·k·period (for a speed that changes monotonically between
        the samples the travel lies between v_prev·τ and v·τ: the trapezoid is off by at most that).
        `limit`: max_periods beyond the ticks between the two frames' arrivals — a frame delayed by
        up to max_periods against its predecessor, after however long a gap (a host that stalled:
        the wheel turned on meanwhile, and its travel over the gap is no new origin)."""
        step = 0.5 * (v_prev + vel) * self.period
        k = 1 if abs(step) < 1e-12 else min(max(round(increment / step), 1), limit)
        bound = tolerance + 0.5 * abs(vel - v_prev) * k * self.period
        return k if abs(increment - k * step) <= bound else None
