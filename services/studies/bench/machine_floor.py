"""The floor the machine allows a periodic loop: a loop that does the daemon's amount of work and nothing else.

The controller daemon's period is I/O (CAN frames in and out, Zenoh) around Python computation:
the tick up to the torque frames (odometry, operator input, the control step, packing), then
telemetry and reading frames until the next tick. This loop keeps the timing and the amounts
and drops the project's computation: a fresh process (no Zenoh threads, so no other thread can hold
the GIL), its thread at SCHED_FIFO where permitted (and on `cpu` alone if given, as the daemon's loop
under `--cpu`), the daemon's `RateClock` with the same spin, and in every period the same
pure-Python float workload in two parts, each calibrated once to thread CPU time: `pre_send_us`,
after which the loop notes the instant a torque frame would leave, and the rest up to `work_us`.
With `hold_us` (the daemon's `--torque-at-us`) that instant waits, as the daemon's frames do, until
`hold_us` after the deadline if the work before it ended earlier.
A deadline counts as missed exactly as the daemon counts it (periods skipped, or a tick started
more than half a period late); the "send" instants give the period jitter |Δt − T| the bench
measures on the bus for the daemon, with the work before them but without a bus.

On the bus (`can_port`, a udp_multicast port): the loop also does the daemon's CAN I/O, as the
daemon does it — at the tick start it reads the frames that are waiting, at the send instant it
writes three Set_Input_Torque frames of 0 N·m to the drives (so the robot and the bench's
listener handle what they handle with the daemon), and after the work it reads frames as they
come until `RECEIVE_MARGIN` before the clock's spin, waking at least every `RECEIVE_SLICE`. The
I/O's own thread CPU is measured first (half a second of the I/O alone at the rate) and taken
off the calibrated work, so the period's CPU stays the daemon's. The bench (stack_run.py) runs
this loop in turns with the daemon, beside the same robot, listener and probes: the floor under
the daemon's own neighbours, in the same minutes.

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

from sharedctl.protocol import cansimple
from sharedctl.protocol.canframe import DEFAULT_WHEEL_NODES

from sharedctl.services.controller.priority import make_loop_realtime, pin_to_cpu
from sharedctl.services.lifecycle import RateClock, poll_until
from .statistics import percentiles

RECEIVE_MARGIN = 2e-4     # s, as the daemon's (services/controller/daemon.py)
RECEIVE_SLICE = 5e-4      # s, as the daemon's
IO_WARM_UP = 0.5          # s of the I/O alone, at the rate, to measure its CPU


def _work(iterations: int) -> float:
    """A fixed piece of pure-Python float arithmetic (what the daemon's tick is made of)."""
    x, y = 0.5, 0.25
    for _ in range(iterations):
        x = x * 0.999 + y * 0.001
        y = y * 0.998 + x * 0.002
    return x + y


def _calibrate(work_us: float) -> int:
    """Iterations whose median thread CPU time is ≈ work_us (median of 50 timings at the final size); 0 for
    less than a microsecond."""
    if work_us < 1.0:
        return 0
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


class BusIO:
    """The daemon's per-period CAN I/O on `transport` (services/can_transport/), without handling the frames."""

    def __init__(self, transport, nodes=DEFAULT_WHEEL_NODES) -> None:
        self.transport = transport
        self.torque = [cansimple.torque_frame(n, 0.0) for n in nodes]
        self.rx = self.tx = 0

    def drain(self) -> None:
        """The frames waiting now."""
        self.rx += len(self.transport.read(2000))

    def send(self) -> None:
        for arb, data in self.torque:
            self.transport.send(arb, False, 8, data)
        self.tx += len(self.torque)

    def read_until(self, deadline: float) -> None:
        """Frames as they come until `deadline` (monotonic), waking at least every RECEIVE_SLICE."""
        while True:
            now = time.monotonic()
            if now >= deadline:
                return
            try:
                frame = self.transport.recv(min(deadline - now, RECEIVE_SLICE))
            except self.transport.UNREADABLE:
                self.transport.bad += 1
                continue
            self.rx += frame is not None


def _io_cost(io: BusIO, period: float, spin: float) -> tuple[float, float, float]:
    """Median thread CPU (µs) of the period's three pieces of I/O — the drain at the tick start, the three
    sends, the reading after them — over IO_WARM_UP s of the I/O alone at the rate."""
    clock = RateClock(period, spin=spin)
    pieces = []
    for _ in range(max(1, int(IO_WARM_UP / period))):
        clock.wait()
        c0 = time.thread_time_ns()
        io.drain()
        c1 = time.thread_time_ns()
        io.send()
        c2 = time.thread_time_ns()
        io.read_until(clock.next - spin - RECEIVE_MARGIN)
        pieces.append((c1 - c0, c2 - c1, time.thread_time_ns() - c2))
    drain, send, read = np.median(np.asarray(pieces, dtype=float), axis=0) / 1e3
    return float(drain), float(send), float(read)


def _loop(rate_hz: float, seconds: float, work_us: float, spin: float, pre_send_us: float | None,
          cpu: int | None, can_port: int | None = None, hold_us: float = 0.0) -> dict:
    realtime = make_loop_realtime()
    pinned = cpu is not None and pin_to_cpu(cpu)
    period = 1.0 / rate_hz
    pre_us = work_us if pre_send_us is None else min(pre_send_us, work_us)
    bus = io = None
    if can_port is not None:
        from sharedctl.services import can_bus

        bus = can_bus.open_transport(can_bus.resolve("udp_multicast", None, {"port": can_port}))
        io = BusIO(bus)
    try:
        io_drain, io_send, io_read = _io_cost(io, period, spin) if io is not None else (0.0, 0.0, 0.0)
        pre = _calibrate(pre_us - io_drain)
        # the hold polls the clock from the end of the work before it to `hold_us` after the deadline (thread
        # CPU, as the daemon's does, ≈ hold_us − pre_us at the median): not calibrated work
        post = _calibrate(work_us - pre_us - io_send - io_read - max(hold_us - pre_us, 0.0))
        ticks = int(seconds * rate_hz)
        lateness, wall, cpu_ns = np.empty(ticks), np.empty(ticks), np.empty(ticks)
        sent, pre_wall = np.empty(ticks), np.empty(ticks)
        steal0 = steal_seconds()
        started = time.time()
        clock = RateClock(period, spin=spin)
        late = 0
        for k in range(ticks):
            lateness[k] = clock.wait()
            deadline = clock.next - period
            late += lateness[k] > period / 2
            w0, c0 = time.perf_counter_ns(), time.thread_time_ns()
            if io is not None:
                io.drain()
            _work(pre)
            if hold_us > 0:
                poll_until(deadline + hold_us * 1e-6)
            if io is not None:
                io.send()
            sent[k] = time.perf_counter_ns()
            _work(post)
            wall[k] = time.perf_counter_ns() - w0
            if io is not None:
                io.read_until(clock.next - spin - RECEIVE_MARGIN)
            cpu_ns[k] = time.thread_time_ns() - c0
            pre_wall[k] = sent[k] - w0
        steal1 = steal_seconds()
        window = (started, time.time())
    finally:
        if bus is not None:
            bus.shutdown()
    return {
        "rate_hz": rate_hz, "seconds": seconds, "work_us": work_us, "pre_send_us": pre_us, "hold_us": hold_us,
        "realtime": realtime,
        "cpu": cpu if pinned else None, "ticks": ticks, "missed": int(clock.missed), "late": int(late),
        "on_bus": io is not None, "io_thread_cpu_us": {"drain": io_drain, "send": io_send, "read": io_read},
        "frames": {"rx": io.rx, "tx": io.tx} if io is not None else None, "window": window,
        "steal_s": None if steal0 is None or steal1 is None else steal1 - steal0,
        "samples": {"lateness": lateness, "wall": wall, "cpu": cpu_ns, "sent": sent, "pre_wall": pre_wall},
    }


def figures(runs: list[dict]) -> dict:
    """The floor's figures over one or more runs of `_loop` (turns of the same loop): counts summed,
    percentiles over all ticks, the period jitter within each run (never across the gap between two)."""
    first = runs[0]

    def cat(name):
        return np.concatenate([r["samples"][name] for r in runs])

    def us(a):
        return {k: v / 1e3 for k, v in percentiles(a).items() if k != "n"}

    lateness, wall, pre_wall = cat("lateness"), cat("wall"), cat("pre_wall")
    jitter = np.concatenate([np.abs(np.diff(r["samples"]["sent"]) - 1e9 / r["rate_hz"]) for r in runs])
    steals = [r["steal_s"] for r in runs]
    missed, late = sum(r["missed"] for r in runs), sum(r["late"] for r in runs)
    out = {k: first[k] for k in ("rate_hz", "work_us", "pre_send_us", "hold_us", "realtime", "cpu", "on_bus")}
    out.update({
        "seconds": sum(r["seconds"] for r in runs), "runs": len(runs), "ticks": sum(r["ticks"] for r in runs),
        "deadline_misses": missed + late, "missed": missed, "late": late,
        "lateness_us": us(lateness * 1e9), "work_wall_us": us(wall), "work_thread_cpu_us": us(cat("cpu")),
        "pre_send_wall_us": us(pre_wall), "send_jitter_us": us(jitter),
        "deadline_to_send_us": us(lateness * 1e9 + pre_wall),
        "ticks_over_half_period": int((wall > 0.5e9 / first["rate_hz"]).sum()),
        "steal_s": None if any(s is None for s in steals) else sum(steals),
    })
    if first["on_bus"]:
        out["io_thread_cpu_us"] = first["io_thread_cpu_us"]
    return out


class FloorProcess:
    """The loop in a fresh process (spawned: no threads inherited), its raw run sent back over a pipe."""

    def __init__(self, *args) -> None:
        context = multiprocessing.get_context("spawn")
        self.pipe, child_end = context.Pipe(duplex=False)
        self.process = context.Process(target=_child, args=(child_end, args), daemon=True)
        self.process.start()
        child_end.close()

    def done(self) -> bool:
        return self.pipe.poll() or not self.process.is_alive()

    def result(self, timeout: float) -> dict:
        """The raw run (for `figures`); raises what the loop raised, or RuntimeError if none came in `timeout` s."""
        if not self.pipe.poll(timeout):
            raise RuntimeError(f"the floor's loop sent nothing in {timeout:.0f} s (exit code {self.process.exitcode})")
        try:
            raw = self.pipe.recv()
        except EOFError:
            self.process.join(1.0)
            raise RuntimeError(f"the floor's loop sent nothing: its process ended "
                               f"(exit code {self.process.exitcode})") from None
        if isinstance(raw, BaseException):
            raise raw
        return raw

    def close(self) -> None:
        """Reap the process (this one's own child, by its handle): a last SIGTERM, then SIGKILL, if still running."""
        self.process.join(2.0)
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(2.0)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()
        self.pipe.close()

    def __enter__(self) -> FloorProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _child(conn, args) -> None:
    try:
        conn.send(_loop(*args))
    except BaseException as exc:  # noqa: BLE001 — sent to the parent, which raises it
        conn.send(RuntimeError(f"the floor's loop failed: {type(exc).__name__}: {exc}"))
    finally:
        conn.close()


def run(rate_hz: float = 500.0, seconds: float = 20.0, work_us: float = 400.0, spin: float = 1e-4,
        pre_send_us: float | None = None, cpu: int | None = None, can_port: int | None = None,
        hold_us: float = 0.0) -> FloorProcess:
    """Start the loop in a fresh process; the caller takes its raw run with `result` and `close`s it."""
    return FloorProcess(rate_hz, seconds, work_us, spin, pre_send_us, cpu, can_port, hold_us)


def measure(rate_hz: float = 500.0, seconds: float = 20.0, work_us: float = 400.0, spin: float = 1e-4,
            pre_send_us: float | None = None, cpu: int | None = None, can_port: int | None = None,
            hold_us: float = 0.0) -> dict:
    """Run the loop in a fresh process and return its figures: `work_us` of thread CPU per period, of which
    `pre_send_us` (default: all) before the "send" instant, which is held until `hold_us` after the deadline
    if that is later (the daemon's `--torque-at-us`); on the udp_multicast bus `can_port` if given."""
    with run(rate_hz, seconds, work_us, spin, pre_send_us, cpu, can_port, hold_us) as loop:
        return figures([loop.result(seconds + 60.0)])


if __name__ == "__main__":
    import json
    print(json.dumps(measure(seconds=10.0), indent=1))
