"""The controller loop's statistics: an observer beside the loop, and the summary it builds at exit.

The loop (daemon.py) notifies `LoopStats` at named points of each period, in this order:

    period_start(lateness, skipped, reached_in_time, reached)   the clock released the tick
    sensor_wait(arrived)              the tick waited for its period's wheel estimates (phase.py)
    torques_ready(tick_start)         its torques are computed (before `torque_at` holds them)
    torque_limited()                  … and were scaled down to the torque limit
    torques_sent(tick_start, age)     its torque frames were handed to the bus
    estop()                           the loop stopped the axes
    tick_done(tick_start)             its work (control and telemetry) is over
    period_end()                      the reading after it is over too: the period's thread CPU and work

Each point costs a clock read, a few counter increments and at most two histogram adds; nothing is
allocated but on a missed deadline. `summary(missed, counts)` is the run as a dict, units in the key
names (`sharedctl controller --json OUT` writes it); `summary_line` is the line printed for people.

Figures (each over the whole run, in 10 µs bins, `LatenessHistogram`):
  jitter      the tick's lateness after its deadline (the clock's wake-up)
  compute     tick start → its work done (control and telemetry)
  torque_ready / torque_out   tick start → torques computed / torque frames handed to the bus
  sensor_to_torque            arrival of the oldest wheel estimate a tick used → its torque frames sent
  loop_cpu    the loop thread's CPU time per period, outside the clock's wait
Missed and late deadlines (a tick started more than half a period late) are put down to a cause
(`MissCauses`); the first of them are kept with the time they happened.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np


class LatenessHistogram:
    """Durations in 10 µs bins up to 50 ms (quantiles over the whole run, fixed memory), their count and sum."""

    BIN = 1e-5

    def __init__(self, bins: int = 5000) -> None:
        self.counts = np.zeros(bins + 1, dtype=np.int64)
        self.last = bins
        self.n = 0
        self.total = 0.0      # s, the durations' sum
        self.max = 0.0

    def add(self, duration: float) -> None:
        self.counts[min(int(duration / self.BIN), self.last)] += 1
        self.n += 1
        self.total += duration
        if duration > self.max:
            self.max = duration

    def quantile(self, p: float) -> float:
        if self.n == 0:
            return 0.0
        k = int(np.searchsorted(np.cumsum(self.counts), math.ceil(p * self.n)))
        return (k + 1) * self.BIN


@dataclass
class MissCauses:
    """Why the loop missed deadlines, from its own clock and CPU time (no extra load).

    For each tick whose deadline was missed or met more than half a period late, the period
    before it is one of:
      * woke late: the loop was waiting in time (it reached the clock before the deadline) and
        the thread came back half a period or more after it: it was not run while asleep or
        polling — on its own real-time CPU, the machine's doing (hypervisor, kernel);
      * overran while not running: its period's work ended after the deadline, yet used no more
        than `WORKING` × the median thread CPU per period: the thread was not run for much of it;
      * overran while working: the work ended after the deadline and used more than that CPU —
        the loop's own cost, or the vCPU running slower: the work those periods handled (CAN frames,
        operator messages) beside their CPU says which.
    Counted in the unit of `missed + late`. The first `KEEP` are kept with the time they happened
    (`at`, s since the loop started): whether misses come at start-up or anywhere says which work to look at."""

    WORKING = 2.0
    KEEP = 12

    woke_late: int = 0
    not_run: int = 0
    working: int = 0
    working_cpu: list = field(default_factory=list)   # s of thread CPU of each period that overran while working
    working_work: list = field(default_factory=list)  # (CAN frames, operator messages) each of those handled
    times: list = field(default_factory=list)         # (at, cause) of the first KEEP notes

    def note(self, count: int, reached_clock_in_time: bool, period_cpu: float, median_cpu: float,
             work: tuple[int, int] = (0, 0), at: float | None = None) -> None:
        if count <= 0:
            return
        if reached_clock_in_time:
            self.woke_late += count
            cause = "woke late"
        elif period_cpu > self.WORKING * median_cpu:
            self.working += count
            self.working_cpu.append(period_cpu)
            self.working_work.append(work)
            cause = "working"
        else:
            self.not_run += count
            cause = "not running"
        if at is not None and len(self.times) < self.KEEP:
            self.times.append((at, cause))

    def working_cpu_p50(self) -> float:
        return float(np.median(self.working_cpu)) if self.working_cpu else 0.0

    def working_work_p50(self) -> tuple[float, float]:
        """Median CAN frames and operator messages handled in the periods that overran while working."""
        if not self.working_work:
            return 0.0, 0.0
        frames, commands = zip(*self.working_work)
        return float(np.median(frames)), float(np.median(commands))


class LoopStats:
    """The loop's observer (module doc). `frames.rx_frames` (the CAN master's frames read) and
    `commands.taken` (the operator messages taken) are read at each period's start and end: the work
    the period handled."""

    def __init__(self, period: float, torque_at: float = 0.0, frames=None, commands=None) -> None:
        self.period = period
        self.torque_at = torque_at
        self.frames, self.commands = frames, commands
        self.jitter = LatenessHistogram()
        self.compute = LatenessHistogram()
        self.torque_ready = LatenessHistogram()
        self.torque_out = LatenessHistogram()
        self.sensor_to_torque = LatenessHistogram()
        self.loop_cpu = LatenessHistogram()
        self.miss_causes = MissCauses()
        self.ticks = 0
        self.late = 0
        self.sensor_waits = 0                 # ticks that waited for their period's wheel estimates
        self.sensor_waits_in_vain = 0         # … and started without them
        self.estops = 0
        self.torque_limited_ticks = 0
        self.t0 = self.cpu0 = 0.0
        self._period_cpu = 0.0                # the last whole period's thread CPU and work
        self._period_frames = self._period_commands = 0
        self._cpu_at_start = 0.0
        self._frames_at_start = self._commands_at_start = 0

    def start(self) -> float:
        """The loop's clock starts: the summary's elapsed time and process CPU count from here (returned)."""
        self.cpu0, self.t0 = time.process_time(), time.monotonic()
        return self.t0

    # ---------------------------------------------------------------- points
    def period_start(self, lateness: float, skipped: int, reached_in_time: bool, reached: float) -> None:
        """The clock released the tick `lateness` s after its deadline, having skipped `skipped` deadlines;
        the loop had reached the clock (at `reached`) before the deadline or not."""
        self._cpu_at_start = time.thread_time()
        self.jitter.add(lateness)
        late = lateness > 0.5 * self.period
        self.late += late
        misses = skipped + late
        if misses and self.ticks:     # (the median's cumulative sum only for a tick that missed)
            self.miss_causes.note(misses, reached_in_time, self._period_cpu, self.loop_cpu.quantile(0.5),
                                  (self._period_frames, self._period_commands), at=reached - self.t0)
        self._frames_at_start, self._commands_at_start = self.frames.rx_frames, self.commands.taken

    def sensor_wait(self, arrived: bool) -> None:
        self.sensor_waits += 1
        self.sensor_waits_in_vain += not arrived

    def torques_ready(self, tick_start: float) -> None:
        self.torque_ready.add(time.monotonic() - tick_start)

    def torque_limited(self) -> None:
        self.torque_limited_ticks += 1

    def torques_sent(self, tick_start: float, feedback_age: float) -> None:
        """`feedback_age`: the age of the oldest wheel estimate the tick used, at its start."""
        sent = time.monotonic() - tick_start
        self.torque_out.add(sent)
        self.sensor_to_torque.add(sent + feedback_age)

    def estop(self) -> None:
        self.estops += 1

    def tick_done(self, tick_start: float) -> None:
        self.ticks += 1
        self.compute.add(time.monotonic() - tick_start)

    def period_end(self) -> None:
        self._period_cpu = time.thread_time() - self._cpu_at_start
        self._period_frames = self.frames.rx_frames - self._frames_at_start
        self._period_commands = self.commands.taken - self._commands_at_start
        self.loop_cpu.add(self._period_cpu)

    # --------------------------------------------------------------- summary
    def summary(self, missed: int, counts: dict | None = None) -> dict:
        """The run so far (`missed`: the deadlines the clock skipped), with the process's `counts` added."""
        elapsed = time.monotonic() - self.t0
        cpu = time.process_time() - self.cpu0
        causes = self.miss_causes
        frames_p50, commands_p50 = causes.working_work_p50()
        out = {
            "ticks": self.ticks, "elapsed_s": elapsed, "rate_hz": self.ticks / elapsed if elapsed > 0 else 0.0,
            "missed": missed, "late": self.late,
            "jitter_p50_us": _us(self.jitter.quantile(0.5)), "jitter_p99_us": _us(self.jitter.quantile(0.99)),
            "jitter_max_us": _us(self.jitter.max),
            "cpu_percent": 100.0 * cpu / elapsed if elapsed > 0 else 0.0,
        }
        for name in ("compute", "torque_ready", "torque_out", "sensor_to_torque", "loop_cpu"):
            histogram = getattr(self, name)
            out[f"{name}_p50_us"], out[f"{name}_p99_us"] = _us(histogram.quantile(0.5)), _us(histogram.quantile(0.99))
        out.update({
            "torque_at_us": _us(self.torque_at),
            "sensor_waits": self.sensor_waits, "sensor_waits_in_vain": self.sensor_waits_in_vain,
            "misses_woke_late": causes.woke_late, "misses_not_run": causes.not_run, "misses_working": causes.working,
            "misses_working_cpu_p50_us": _us(causes.working_cpu_p50()),
            "misses_working_frames_p50": frames_p50, "misses_working_commands_p50": commands_p50,
            "miss_times": [{"t_s": round(at, 6), "cause": cause} for at, cause in causes.times],
            "estops": self.estops, "torque_limited_ticks": self.torque_limited_ticks,
        })
        out.update(counts or {})
        return out


def _us(seconds: float) -> float:
    return round(seconds * 1e6, 3)


def summary_line(s: dict) -> str:
    """The summary as the one line the controller prints at exit, for people (nothing parses it: `--json`)."""
    def ms(key: str) -> float:
        return s[key] / 1e3              # the line keeps its milliseconds
    rejections = s.get("rejections", {})
    detail = ", ".join(f"{k} {v}" for k, v in sorted(rejections.items()))
    return (
        f"sharedctl controller: stopped after {s['elapsed_s']:.1f} s: {s['ticks']} ticks at {s['rate_hz']:.1f} Hz, "
        f"{s['missed']} missed / {s['late']} late deadlines, jitter p50 {ms('jitter_p50_us'):.3f} ms "
        f"p99 {ms('jitter_p99_us'):.3f} ms max {ms('jitter_max_us'):.2f} ms, compute p50 {ms('compute_p50_us'):.3f} ms "
        f"p99 {ms('compute_p99_us'):.3f} ms, torque out p50 {ms('torque_out_p50_us'):.3f} ms p99 "
        f"{ms('torque_out_p99_us'):.3f} ms, sensor to torque p50 {ms('sensor_to_torque_p50_us'):.3f} ms p99 "
        f"{ms('sensor_to_torque_p99_us'):.3f} ms, loop thread CPU p50 {ms('loop_cpu_p50_us'):.3f} ms p99 "
        f"{ms('loop_cpu_p99_us'):.3f} ms per period, CPU {s['cpu_percent']:.0f}% of one core; "
        f"CAN frames rx {s.get('frames_rx', 0)} tx {s.get('frames_tx', 0)} bad {s.get('bad_frames', 0)}, implausible "
        f"encoder values {s.get('implausible_estimates', 0)}; operator commands {s.get('commands_accepted', 0)} "
        f"accepted, {sum(rejections.values())} rejected{f' ({detail})' if detail else ''}; "
        f"estops {s['estops']}, torque-limited ticks {s['torque_limited_ticks']}; ticks that waited for their wheel "
        f"estimates {s['sensor_waits']} ({s['sensor_waits_in_vain']} in vain); missed and late deadlines by "
        f"cause: {s['misses_woke_late']} woke late, {s['misses_not_run']} overran while not running, "
        f"{s['misses_working']} overran while working (thread CPU p50 {ms('misses_working_cpu_p50_us'):.3f} ms, "
        f"CAN frames p50 {s['misses_working_frames_p50']:g}, operator messages p50 "
        f"{s['misses_working_commands_p50']:g}); torques computed p50 {ms('torque_ready_p50_us'):.3f} ms p99 "
        f"{ms('torque_ready_p99_us'):.3f} ms, "
        + (f"sent at deadline + {ms('torque_at_us'):.3f} ms" if s["torque_at_us"] > 0 else "sent as soon as computed")
        + "; first misses at: "
        + (", ".join(f"{m['t_s']:.3f} s ({m['cause']})" for m in s["miss_times"]) or "none")
    )
