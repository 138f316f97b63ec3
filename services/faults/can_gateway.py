"""`sharedctl fault-gateway` — a CAN gateway between the controller's bus and the robot's bus
that impairs the frames it forwards (``can.*`` faults).

    controller ── bus A ──▶ [gateway] ──▶ bus B ── robot (simulated ODrives)
               ◀── feedback ───────────── feedback ◀──

Buses: two host-local python-can udp_multicast buses (``--controller-port``/``--robot-port``,
always hop_limit=0 via services/can_bus.py), or two SocketCAN interfaces
(``--interface socketcan --controller-channel vcan0 --robot-channel vcan1``; see
deploy/vcan-setup.sh — the kernel of the development host has no vcan, so that path is
documented and its test is skipped there).

Direction comes from the CANSimple command id (protocol/README.md §1.2): host→drive frames
("command": Estop, Set_*, Clear_Errors and every RTR poll) are forwarded A→B, drive→host data
frames ("feedback": Heartbeat, Get_* replies) B→A. A frame seen on a bus in the direction the
gateway itself sends there is its own udp_multicast echo and is ignored; a frame of no known
direction (e.g. the babble id) is counted as ``unknown`` and never forwarded, so no frame can
loop between the buses.

Impairments (services/faults/impairments.py) act on the frames selected by ``can.ids``
(``feedback``, ``command``, ``all`` or a list of ids); the rest are forwarded at once.
Each direction has its own seeded pipeline (``<seed>:can.command``, ``<seed>:can.feedback``).
The pipeline sees ``id, flags, dlc`` packed in a 4-byte header in front of the data; bit flips
touch only the data (a frame whose corruption passed the CRC, i.e. a faulty node).
``can.busoff=START,DURATION`` windows forward nothing. ``can.babble=HZ[,ID[,START,DURATION]]``
sends a flood of ID (default 0x000, the highest priority) on both buses; udp_multicast has no
arbitration, so what the flood costs there is receive load on every node.

A frame's arrival time is the interface's kernel receive timestamp, so delays, windows and
``latency_ms`` (arrival to send) count from when it reached the gateway, not from when the
gateway got round to reading it; ``buffer_wait_ms`` (mean/max) is that reading lag.

One thread: `select` on both buses' sockets, drain each ready bus in a batch (non-blocking
reads until empty, at most BATCH frames, through services/can_transport/), release what is due
from a heap, babble when due.
As `sharedctl fault-relay`, faults act from SIGUSR1 on (``--arm-on-signal``; windows count from the
run's t = 0 read from ``--origin-file``), counters go to
``--stats FILE`` at exit, including the gateway's CPU time and the frame rate it handled.
"""
from __future__ import annotations

import heapq
import itertools
import select
import signal
import struct
import sys
import time
from pathlib import Path

import can

from ..can_bus import BusSpec, open_transport, resolve
from ..controller.priority import make_loop_realtime
from ..lifecycle import StopFlag
from ..can_transport import Frame, transport_for
from .impairments import Pipeline
from .spec import FaultPlan, FaultSpecError, parse, pipeline
from .zenoh_relay import add_fault_arguments, add_origin_argument, origin_monotonic, write_stats

COMMAND_CMDS = frozenset({0x02, 0x07, 0x0B, 0x0D, 0x0E, 0x0F, 0x18})    # host → drive (data frames)
FEEDBACK_CMDS = frozenset({0x01, 0x03, 0x09, 0x14, 0x17, 0x1C})         # drive → host (data frames)
BATCH = 256                     # frames drained from one bus per pass
HEADER = struct.Struct("<HBB")   # arbitration id, flags (bit 0: remote), dlc
BABBLE_DATA = b"\xba\xbb\x1e\x00\xba\xbb\x1e\x00"


def direction(frame: Frame) -> str | None:
    """``"command"`` (host→drive), ``"feedback"`` (drive→host) or None (not a CANSimple direction)."""
    if frame.is_extended or frame.is_error:
        return None
    cmd = frame.arbitration_id & 0x1F
    if frame.is_remote:
        return "command"
    if cmd in COMMAND_CMDS:
        return "command"
    if cmd in FEEDBACK_CMDS:
        return "feedback"
    return None


def selected(ids: tuple, kind: str, arbitration_id: int) -> bool:
    """Whether ``can.ids`` puts this frame through the impairments."""
    if ids[0] == "all":
        return True
    if ids[0] in ("feedback", "command"):
        return ids[0] == kind
    return arbitration_id in ids


class Stream:
    """One direction: its pipeline and what happened at the send."""

    def __init__(self, pipe: Pipeline) -> None:
        self.pipe = pipe
        self.received = 0
        self.unimpaired = 0
        self.forwarded = 0
        self.send_errors = 0
        self.latency_sum = 0.0
        self.latency_max = 0.0
        self.latency_n = 0
        self.wait_sum = 0.0       # s frames waited in the receive buffer (kernel timestamp → read)
        self.wait_max = 0.0

    def report(self) -> dict:
        n = self.received
        return {**self.pipe.counters,
                "buffer_wait_ms_mean": 1000.0 * self.wait_sum / n if n else None,
                "buffer_wait_ms_max": 1000.0 * self.wait_max if n else None, "stages": self.pipe.describe(),
                "frames_seen": self.received,
                "passed_unimpaired": self.unimpaired, "forwarded": self.forwarded, "send_errors": self.send_errors,
                "latency_ms_mean": 1000.0 * self.latency_sum / self.latency_n if self.latency_n else None,
                "latency_ms_max": 1000.0 * self.latency_max if self.latency_n else None}


class CanGateway:
    """Forward between `controller_bus` (A) and `robot_bus` (B) with the plan's ``can.*`` faults."""

    def __init__(self, controller_bus, robot_bus, plan: FaultPlan) -> None:
        self.buses = {"controller": transport_for(controller_bus), "robot": transport_for(robot_bus)}
        self.link = plan.links["can"]
        self.streams = {kind: Stream(pipeline(plan, f"can.{kind}", corrupt_skip=HEADER.size))
                        for kind in ("command", "feedback")}
        self.heap: list = []
        self.order = itertools.count()
        self.t0: float | None = None
        self.armed_wall: float | None = None      # time.time() of the run's t = 0, for alignment
        self.armed_late: float | None = None      # s after t = 0 the faults were armed (impairments act from then)
        self.echo_ignored = 0
        self.unknown = 0
        self.babble_sent = 0
        self.babble_errors = 0
        self.batches = 0
        self.max_batch = 0
        self.realtime = False
        self.started = time.monotonic()
        self.cpu_start = time.process_time()

    def arm(self, origin: float | None = None) -> None:
        """Faults act from now on; `origin` (monotonic, default now) is the run's t = 0 (windows count from it)."""
        if self.t0 is None:
            now = time.monotonic()
            self.t0 = now if origin is None else min(origin, now)
            self.armed_wall, self.armed_late = time.time() - (now - self.t0), now - self.t0

    # ----- the loop --------------------------------------------------------------
    def run(self, stop: StopFlag, deadline: float | None = None) -> None:
        fds = {bus.fileno(): name for name, bus in self.buses.items()}
        while not stop.stopped and (deadline is None or time.monotonic() < deadline):
            now = time.monotonic()
            timeout = 0.05
            if self.heap:
                timeout = min(timeout, max(0.0, self.heap[0][0] - now))
            if self.link.babble is not None and self.t0 is not None:
                timeout = min(timeout, 0.001)
            try:
                ready, _, _ = select.select(list(fds), [], [], timeout)
            except InterruptedError:
                continue
            for fd in ready:
                self._drain(fds[fd])
            self._release(time.monotonic())
            self._babble(time.monotonic())

    def _drain(self, side: str) -> None:
        frames = self.buses[side].read(BATCH)
        for frame in frames:
            self._on_frame(side, frame)
        self.batches += 1
        self.max_batch = max(self.max_batch, len(frames))

    def _on_frame(self, side: str, msg: Frame) -> None:
        kind = direction(msg)
        if kind is None:
            self.unknown += 1
            return
        if (kind == "command") != (side == "controller"):
            self.echo_ignored += 1       # what this gateway sent on that bus, heard back
            return
        stream = self.streams[kind]
        stream.received += 1
        now = time.monotonic()
        wait = max(0.0, time.time() - msg.arrival)    # the interface's receive time: when the frame arrived
        arrival = now - wait
        stream.wait_sum += wait
        stream.wait_max = max(stream.wait_max, wait)
        target = self.buses["robot" if kind == "command" else "controller"]
        if self.t0 is None or not selected(self.link.ids, kind, msg.arbitration_id):
            stream.unimpaired += 1
            self._send(stream, target, msg, arrival, impaired=False)
            return
        packed = HEADER.pack(msg.arbitration_id, 1 if msg.is_remote else 0, msg.dlc) + msg.data
        for release, payload in stream.pipe.feed(arrival - self.t0, packed):
            when = self.t0 + release
            if when <= now:
                self._send(stream, target, payload, arrival)
            else:
                heapq.heappush(self.heap, (when, next(self.order), kind, payload, arrival))

    def _release(self, now: float) -> None:
        while self.heap and self.heap[0][0] <= now:
            _, _, kind, payload, arrival = heapq.heappop(self.heap)
            stream = self.streams[kind]
            self._send(stream, self.buses["robot" if kind == "command" else "controller"], payload, arrival)

    def _send(self, stream: Stream, port, frame: Frame | bytes, arrival: float, impaired: bool = True) -> None:
        """Forward a frame as it came, or send one rebuilt from a pipeline payload (header + data). The
        latency counts only frames the pipeline held: one forwarded before arming, or outside the id
        filter, is not delayed and would dilute the measured delay."""
        try:
            if isinstance(frame, Frame):
                port.forward(frame)
            else:
                arbitration_id, flags, dlc = HEADER.unpack_from(frame)
                port.send(arbitration_id, bool(flags & 1), dlc, frame[HEADER.size:])
        except (can.CanError, OSError, ValueError, TypeError):
            stream.send_errors += 1
            return
        stream.forwarded += 1
        if impaired:
            latency = time.monotonic() - arrival
            stream.latency_sum += latency
            stream.latency_n += 1
            if latency > stream.latency_max:
                stream.latency_max = latency

    def _babble(self, now: float) -> None:
        if self.link.babble is None or self.t0 is None:
            return
        hz, can_id, start, duration = self.link.babble
        t = now - self.t0
        if not start <= t < start + duration:
            return
        due = int((t - start) * hz) - self.babble_sent // len(self.buses)
        for _ in range(min(due, BATCH)):
            for port in self.buses.values():
                try:
                    port.send(can_id, False, len(BABBLE_DATA), BABBLE_DATA)
                    self.babble_sent += 1
                except (can.CanError, OSError, ValueError):
                    self.babble_errors += 1

    def report(self) -> dict:
        wall = time.monotonic() - self.started
        cpu = time.process_time() - self.cpu_start
        frames = sum(s.received for s in self.streams.values())
        return {"kind": "can-gateway", "armed": self.t0 is not None, "armed_wall": self.armed_wall,
                "armed_late_s": self.armed_late,
                "realtime": self.realtime,
                "ids": list(self.link.ids),
                "command": self.streams["command"].report(), "feedback": self.streams["feedback"].report(),
                "echo_ignored": self.echo_ignored, "unknown": self.unknown, "pending": len(self.heap),
                "unreadable": sum(port.bad for port in self.buses.values()),
                "ports": {side: type(port).__name__ for side, port in self.buses.items()},
                "babble": {"setting": list(self.link.babble) if self.link.babble else None, "sent": self.babble_sent,
                           "errors": self.babble_errors},
                "batches": self.batches, "max_batch": self.max_batch, "wall_seconds": wall, "cpu_seconds": cpu,
                "frames_per_s": frames / wall if wall > 0 else None,
                "cpu_us_per_frame": 1e6 * cpu / frames if frames else None}


# ----- the command ---------------------------------------------------------------
def add_parser(subparsers) -> None:
    p = subparsers.add_parser("fault-gateway", help="CAN gateway that injects can.* faults (demo --fault)",
                              description="CAN gateway between the controller's and the robot's bus that "
                                          "impairs the forwarded frames (can.* faults).")
    p.add_argument("--interface", default="udp_multicast", help="udp_multicast (default) or socketcan")
    p.add_argument("--controller-port", type=int, help="udp_multicast port of the controller's bus")
    p.add_argument("--robot-port", type=int, help="udp_multicast port of the robot's bus")
    p.add_argument("--controller-channel", help="socketcan: the controller's interface (e.g. vcan0)")
    p.add_argument("--robot-channel", help="socketcan: the robot's interface (e.g. vcan1)")
    add_fault_arguments(p)
    p.add_argument("--arm-on-signal", action="store_true", help="faults act from SIGUSR1 on (default: from the start)")
    add_origin_argument(p)
    p.add_argument("--stats", metavar="FILE", help="write the counters as JSON here at exit (default: stdout)")
    p.add_argument("--ready", metavar="FILE", help="create FILE once both buses are open")
    p.add_argument("--duration", type=float, metavar="S", help="exit after S seconds (a backstop)")
    p.add_argument("--realtime", action="store_true",
                   help="SCHED_FIFO like the controller's loop (it is in the torque loop's path), if permitted")
    p.set_defaults(handler=run)


def bus_specs(args) -> tuple[BusSpec, BusSpec]:
    if args.interface == "udp_multicast":
        if args.controller_port is None or args.robot_port is None or args.controller_port == args.robot_port:
            raise ValueError("udp_multicast needs two different --controller-port and --robot-port")
        return (resolve("udp_multicast", None, udp_port=args.controller_port),
                resolve("udp_multicast", None, udp_port=args.robot_port))
    if not args.controller_channel or not args.robot_channel or args.controller_channel == args.robot_channel:
        raise ValueError(f"{args.interface} needs two different --controller-channel and --robot-channel")
    return resolve(args.interface, args.controller_channel), resolve(args.interface, args.robot_channel)


def run(args) -> int:
    stop = StopFlag().install()
    try:
        plan = parse(args.fault, args.fault_seed)
        specs = bus_specs(args)
    except (FaultSpecError, ValueError) as exc:
        print(f"sharedctl fault-gateway: {exc}", file=sys.stderr)
        return 2
    buses = []
    try:
        for spec in specs:
            buses.append(open_transport(spec))
    except (can.CanError, OSError, ValueError) as exc:
        for bus in buses:
            bus.shutdown()
        print(f"sharedctl fault-gateway: cannot open the buses: {exc}", file=sys.stderr)
        return 1
    gateway = CanGateway(buses[0], buses[1], plan)
    gateway.realtime = make_loop_realtime() if args.realtime else False
    signal.signal(signal.SIGUSR1, lambda *_: gateway.arm(origin_monotonic(args.origin_file)))
    if not args.arm_on_signal:
        gateway.arm()
    if args.ready:
        Path(args.ready).write_text("ready\n")
    deadline = None if args.duration is None else time.monotonic() + args.duration
    try:
        gateway.run(stop, deadline)
    finally:
        report = gateway.report()
        for bus in buses:
            bus.shutdown()
        write_stats(report, args.stats)
    return 0
