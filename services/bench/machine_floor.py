"""The floor the machine allows a periodic loop: a loop that does the daemon's amount of work and nothing else.

The controller daemon's period is I/O (CAN frames in and out, Zenoh) around Python computation:
the tick up to the torque frames (odometry, operator input, the control step, packing), then
telemetry and reading frames until the next tick. This loop keeps the timing and the amounts
and drops the I/O: a fresh process (no Zenoh or CAN threads, so no other thread can hold the
GIL), its thread at SCHED_FIFO where permitted (and on `cpu` alone if given, as the daemon's loop
under `--cpu`), the daemon's `RateClock` with the same spin, and in every period the same
pure-Python float workload in two parts, each calibrated once to thread CPU time: `pre_send_us`,
after which the loop notes the instant a torque frame would leave, and the rest up to `work_us`.
A deadline counts as missed exactly as the daemon counts it (periods skipped, or a tick started
more than half a period late); the "send" instants give the period jitter |Δt − T| the bench
measures on the bus for the daemon, with the work before them but without a bus.

What it shows: how much longer the *same* work takes from one period to the next on this host
(wall and thread CPU time per tick — on a virtual machine the vCPU can run slower for a while
when its neighbours on the physical host are busy, which thread CPU time does not hide), and how
many deadlines a loop of this shape misses with nothing of the project in it. The daemon's misses
above this floor are the daemon's; those at it are the machine's.
"""
from __future__ import annotations

import multiprocessing
import os
import time

import numpy as np

from ..controller.priority import make_loop_realtime, pin_to_cpu
from ..lifecycle import RateClock
from .statistics import percentiles


def _work(iterations: int) -> float:
    """A fixed piece of pure-Python float arithmetic (what the daemon's tick is made of)."""
    x, y = 0.5, 0.25
    for _ in range(iterations):
        x = x * 0.999 + y * 0.001
        y = y * 0.998 + x * 0.002
    return x + y


def _calibrate(work_us: float) -> int:
    """Iterations whose median thread CPU time is ≈ work_us (median of 50 timings at the final size)."""
    iterations = 1000
    for _ in range(4):
        samples = []
        for _ in range(50):
            t0 = time.thread_time_ns()
            _work(iterations)
            samples.append(time.thread_time_ns() - t0)
        iterations = max(1, round(iterations * work_us * 1e3 / float(np.median(samples))))
    return iterations


def steal_seconds() -> float | None:
    """The guest's steal time so far (s; /proc/stat): time its vCPUs were ready but the hypervisor ran
    something else. None where the kernel does not report it."""
    try:
        with open("/proc/stat") as f:
            return int(f.readline().split()[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def _loop(rate_hz: float, seconds: float, work_us: float, spin: float, pre_send_us: float | None,
          cpu: int | None) -> dict:
    realtime = make_loop_realtime()
    pinned = cpu is not None and pin_to_cpu(cpu)
    pre_us = work_us if pre_send_us is None else min(pre_send_us, work_us)
    pre = _calibrate(pre_us)
    post = _calibrate(work_us - pre_us) if work_us - pre_us >= 1.0 else 0
    period = 1.0 / rate_hz
    ticks = int(seconds * rate_hz)
    lateness, wall, cpu_ns = np.empty(ticks), np.empty(ticks), np.empty(ticks)
    sent, pre_wall = np.empty(ticks), np.empty(ticks)
    steal0 = steal_seconds()
    clock = RateClock(period, spin=spin)
    late = 0
    for k in range(ticks):
        lateness[k] = clock.wait()
        late += lateness[k] > period / 2
        w0, c0 = time.perf_counter_ns(), time.thread_time_ns()
        _work(pre)
        sent[k] = time.perf_counter_ns()
        if post:
            _work(post)
        wall[k], cpu_ns[k] = time.perf_counter_ns() - w0, time.thread_time_ns() - c0
        pre_wall[k] = sent[k] - w0
    steal1 = steal_seconds()
    us = lambda a: {k: v / 1e3 for k, v in percentiles(a).items() if k != "n"}   # noqa: E731
    return {
        "rate_hz": rate_hz, "seconds": seconds, "work_us": work_us, "pre_send_us": pre_us, "realtime": realtime,
        "cpu": cpu if pinned else None, "ticks": ticks,
        "deadline_misses": int(clock.missed + late), "missed": int(clock.missed), "late": int(late),
        "lateness_us": us(lateness * 1e9), "work_wall_us": us(wall), "work_thread_cpu_us": us(cpu_ns),
        "pre_send_wall_us": us(pre_wall), "send_jitter_us": us(np.abs(np.diff(sent) - period * 1e9)),
        "deadline_to_send_us": us(lateness * 1e9 + pre_wall),
        "ticks_over_half_period": int((wall > period * 0.5e9).sum()),
        "steal_s": None if steal0 is None or steal1 is None else steal1 - steal0,
    }


def measure(rate_hz: float = 500.0, seconds: float = 20.0, work_us: float = 400.0, spin: float = 1e-4,
            pre_send_us: float | None = None, cpu: int | None = None) -> dict:
    """Run the loop in a fresh process (spawned: no threads inherited) and return its figures: `work_us` of
    thread CPU per period, of which `pre_send_us` (default: all) before the noted "send" instant."""
    with multiprocessing.get_context("spawn").Pool(1) as pool:
        return pool.apply(_loop, (rate_hz, seconds, work_us, spin, pre_send_us, cpu))


if __name__ == "__main__":
    import json
    print(json.dumps(measure(seconds=10.0), indent=1))
