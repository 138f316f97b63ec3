"""The controller loop's own timing record: fixed-memory histograms and the exit summary line.

The summary line is parsed by `sharedctl bench` (services/bench/stack_run.py) and the fault
campaign: keep its wording.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


class LatenessHistogram:
    """Tick lateness in 10 µs bins up to 50 ms (quantiles over the whole run, fixed memory)."""

    BIN = 1e-5

    def __init__(self, bins: int = 5000) -> None:
        self.counts = np.zeros(bins + 1, dtype=np.int64)
        self.n = 0
        self.max = 0.0

    def add(self, lateness: float) -> None:
        self.counts[min(int(lateness / self.BIN), len(self.counts) - 1)] += 1
        self.n += 1
        self.max = max(self.max, lateness)

    def quantile(self, p: float) -> float:
        if self.n == 0:
            return 0.0
        k = int(np.searchsorted(np.cumsum(self.counts), math.ceil(p * self.n)))
        return (k + 1) * self.BIN


@dataclass
class Summary:
    ticks: int = 0
    elapsed: float = 0.0
    rate: float = 0.0
    missed: int = 0
    late: int = 0
    jitter_p50_ms: float = 0.0
    jitter_p99_ms: float = 0.0
    jitter_max_ms: float = 0.0
    cpu_percent: float = 0.0
    compute_p50_ms: float = 0.0
    compute_p99_ms: float = 0.0
    torque_out_p50_ms: float = 0.0
    torque_out_p99_ms: float = 0.0
    torque_ready_p50_ms: float = 0.0   # tick start → torques computed (before the output instant holds them)
    torque_ready_p99_ms: float = 0.0
    torque_at_ms: float = 0.0          # the output instant after each deadline (0: as soon as computed)
    sensor_to_torque_p50_ms: float = 0.0   # arrival of the oldest wheel estimate a tick used → its torque frames sent
    sensor_to_torque_p99_ms: float = 0.0
    loop_cpu_p50_ms: float = 0.0       # the loop thread's CPU time per period outside the clock's wait
    loop_cpu_p99_ms: float = 0.0
    frames_rx: int = 0
    frames_tx: int = 0
    bad_frames: int = 0
    implausible_estimates: int = 0
    commands_accepted: int = 0
    rejections: dict = field(default_factory=dict)
    estops: int = 0
    saturated: int = 0
    mode: str = ""
    sensor_waits: int = 0
    sensor_wait_timeouts: int = 0
    misses_woke_late: int = 0          # missed/late deadlines by cause (MissCauses)
    misses_not_run: int = 0
    misses_working: int = 0
    working_cpu_p50_ms: float = 0.0    # the loop thread's CPU in the periods that overran while working
    working_frames_p50: float = 0.0    # … the CAN frames and operator messages those periods handled
    working_commands_p50: float = 0.0
    miss_times: tuple = ()             # (s since the loop started, cause) of the first missed/late deadlines

    def line(self) -> str:
        rej = sum(self.rejections.values())
        detail = ", ".join(f"{k} {v}" for k, v in sorted(self.rejections.items()))
        return (
            f"sharedctl controller: stopped after {self.elapsed:.1f} s: {self.ticks} ticks at {self.rate:.1f} Hz, "
            f"{self.missed} missed / {self.late} late deadlines, jitter p50 {self.jitter_p50_ms:.3f} ms "
            f"p99 {self.jitter_p99_ms:.3f} ms max {self.jitter_max_ms:.2f} ms, compute p50 {self.compute_p50_ms:.3f} ms "
            f"p99 {self.compute_p99_ms:.3f} ms, torque out p50 {self.torque_out_p50_ms:.3f} ms p99 "
            f"{self.torque_out_p99_ms:.3f} ms, sensor to torque p50 {self.sensor_to_torque_p50_ms:.3f} ms p99 "
            f"{self.sensor_to_torque_p99_ms:.3f} ms, loop thread CPU p50 {self.loop_cpu_p50_ms:.3f} ms p99 {self.loop_cpu_p99_ms:.3f} ms "
            f"per period, CPU {self.cpu_percent:.0f}% of one core; "
            f"CAN frames rx {self.frames_rx} tx {self.frames_tx} bad {self.bad_frames}, implausible encoder values "
            f"{self.implausible_estimates}; operator commands "
            f"{self.commands_accepted} accepted, {rej} rejected{f' ({detail})' if detail else ''}; "
            f"estops {self.estops}, torque-limited ticks {self.saturated}; ticks that waited for their wheel "
            f"estimates {self.sensor_waits} ({self.sensor_wait_timeouts} in vain); missed and late deadlines by "
            f"cause: {self.misses_woke_late} woke late, {self.misses_not_run} overran while not running, "
            f"{self.misses_working} overran while working (thread CPU p50 {self.working_cpu_p50_ms:.3f} ms, "
            f"CAN frames p50 {self.working_frames_p50:g}, operator messages p50 {self.working_commands_p50:g}); "
            f"torques computed p50 {self.torque_ready_p50_ms:.3f} ms p99 {self.torque_ready_p99_ms:.3f} ms, "
            + (f"sent at deadline + {self.torque_at_ms:.3f} ms" if self.torque_at_ms > 0 else "sent as soon as computed")
            + "; first misses at: " + (", ".join(f"{t:.3f} s ({cause})" for t, cause in self.miss_times) or "none")
        )


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
