"""The robot process's I/O shell: CAN in/out, Zenoh ground truth and liveliness, the real-time loop.

One thread. Every tick of the physics clock (1 kHz by default):
  1. drain the CAN receive queue (non-blocking, through a services/can_transport/ transport), decode each
     host → drive frame with the CANSimple codec and hand it to the simulation; answer RTR
     polls at once;
  2. advance the simulation to now (watchdogs, RK4 steps) and send the cyclic frames due
     (Heartbeat 10 Hz, Get_Encoder_Estimates 500 Hz per axis);
  3. publish GroundTruth on Zenoh when due (100 Hz) and a Heartbeat message once a second.
Frames of the drive → host direction (our own echoes on udp_multicast) are skipped before
decoding; frames the codec refuses are counted and skipped; a frame never crashes the loop.
"""
from __future__ import annotations

import gc
import os
import sys
import time
from collections import Counter
from dataclasses import dataclass

import can

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol import keys
from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.messages import GroundTruth, Heartbeat
from sharedctl.protocol.msgpack_codec import encode_message

from .. import zenoh_qos
from ..can_transport import Frame, Transport, transport_for
from ..lifecycle import RateClock, StopFlag
from .simulation import RobotSimulation, is_own_direction

ROLE = "robot"
MAX_FRAMES_PER_TICK = 500


@dataclass
class CpuMeter:
    """Process CPU time (all threads) over wall time, as a fraction of one core."""

    def __post_init__(self) -> None:
        self.cpu0, self.wall0 = self._cpu(), time.monotonic()

    @staticmethod
    def _cpu() -> float:
        t = os.times()
        return t.user + t.system

    def fraction(self) -> float:
        wall = time.monotonic() - self.wall0
        return (self._cpu() - self.cpu0) / wall if wall > 0 else 0.0


class RobotProcess:
    """Wires a `RobotSimulation` to an open CAN bus and an open Zenoh session (both owned by the caller).

    `bus` is a transport (services/can_transport/), or a python-can bus, wrapped in the generic one."""

    def __init__(self, sim: RobotSimulation, bus: Transport | can.BusABC, session, robot_id: str) -> None:
        self.sim = sim
        self.bus = bus
        self.transport = transport_for(bus)
        self.session = session
        self.robot_id = robot_id
        self.nodes = tuple(sim.by_node)
        self.counts: Counter = Counter()
        self.truth_seq = 0
        self.heartbeat_seq = 0
        self.truth_publisher = zenoh_qos.declare_publisher(session, keys.truth_key(robot_id)) if session else None
        self.alive_publisher = zenoh_qos.declare_publisher(session, keys.alive_key(robot_id, ROLE)) if session else None
        self.token = session.liveliness().declare_token(keys.alive_key(robot_id, ROLE)) if session else None
        self.drive_restart = (1, 0.5)                       # (axis, s silent) a restart request means
        self._restart_requested = False
        self.clock_start = time.monotonic()                 # `now` = monotonic − clock_start
        self.clock: RateClock | None = None                 # the loop's clock, once `run` has started it
        self.wall_minus_monotonic = time.time() - time.monotonic()

    # ----- CAN -------------------------------------------------------------------
    def send(self, frame) -> None:
        f = cs.encode(frame)
        try:
            self.transport.send(f.arbitration_id, f.is_remote, f.dlc, f.data)
            self.counts["frames_out"] += 1
        except (can.CanError, OSError):
            self.counts["send_errors"] += 1

    def receive_pending(self, now: float) -> None:
        for _ in range(MAX_FRAMES_PER_TICK):
            try:
                frame = self.transport.recv(0.0)
            except (can.CanError, OSError, ValueError):
                self.counts["bad_frames"] += 1
                continue
            if frame is None:
                return
            self.handle_message(frame, now)

    def frame_time(self, msg: Frame, now: float) -> float:
        """When the frame arrived (s, loop time), from its receive timestamp; `now` if that is implausible.

        A frame that waited in the socket while this process was not scheduled counts from its
        arrival, so a stall of the simulator itself never trips a drive's watchdog.
        """
        stamp = msg.arrival
        if not stamp:
            return now
        at = stamp - self.wall_minus_monotonic - self.clock_start
        return at if now - 1.0 <= at <= now else now

    def handle_message(self, msg: Frame, now: float) -> None:
        if msg.is_error:
            self.counts["error_frames"] += 1
            return
        if not msg.is_extended:
            if is_own_direction(msg.arbitration_id, msg.is_remote):
                self.counts["echoes"] += 1
                return
            if (msg.arbitration_id >> 5) not in self.nodes:
                self.counts["other_nodes"] += 1
                return
        try:
            frame = cs.decode(msg.arbitration_id, msg.data, msg.is_remote, dlc=msg.dlc,
                              is_extended_id=msg.is_extended, nodes=self.nodes)
        except ProtocolError:
            self.counts["bad_frames"] += 1
            return
        self.counts["frames_in"] += 1
        for reply in self.sim.receive(frame, self.frame_time(msg, now)):
            self.send(reply)

    # ----- Zenoh -----------------------------------------------------------------
    def publish_truth(self) -> None:
        if self.truth_publisher is None:
            return
        state = self.sim.state
        message = GroundTruth(seq=self.truth_seq, time=self.sim.time, q=tuple(map(float, state.q)),
                              qd=tuple(map(float, state.qd)))
        self.truth_publisher.put(encode_message(message))
        self.truth_seq += 1

    def publish_heartbeat(self, now: float) -> None:
        if self.alive_publisher is None:
            return
        self.alive_publisher.put(encode_message(Heartbeat(role=ROLE, id=self.robot_id, seq=self.heartbeat_seq,
                                                          time=now)))
        self.heartbeat_seq += 1

    # ----- loop ------------------------------------------------------------------
    def run(self, stop: StopFlag, duration: float | None = None, spin: float = 0.0) -> None:
        """The loop; `spin` (s) before each tick is polled rather than slept (lifecycle.RateClock)."""
        gc.collect()
        gc.freeze()          # start-up objects out of the collector's way: shorter pauses in the loop
        self.clock = clock = RateClock(self.sim.dt, spin=spin)
        self.clock_start = clock.start
        self.wall_minus_monotonic = time.time() - time.monotonic()
        next_heartbeat = 0.0
        while not stop.stopped:
            now = clock.elapsed()
            if duration is not None and now >= duration:
                break
            if self._restart_requested:
                self._restart_requested = False
                self.sim.restart_drive(*self.drive_restart, now)
            self.receive_pending(now)
            for frame in self.sim.advance(now):
                self.send(frame)
            if self.sim.truth_due(now):
                self.publish_truth()
            if now >= next_heartbeat:
                self.publish_heartbeat(now)
                next_heartbeat = now + 1.0
            clock.wait()
        self.counts["missed_ticks"] = clock.missed

    def request_drive_restart(self) -> None:
        """From a signal handler: the loop restarts `drive_restart`'s drive at its next tick."""
        self._restart_requested = True

    def close(self) -> None:
        """Undeclare the liveliness token and publishers (the caller closes session and bus)."""
        for entity in (self.token, self.truth_publisher, self.alive_publisher):
            if entity is not None:
                try:
                    entity.undeclare()
                except Exception as exc:  # noqa: BLE001 — closing must go on
                    print(f"sharedctl robot: undeclare failed: {exc}", file=sys.stderr)

    def summary(self) -> str:
        c = self.counts
        return (f"frames in {c['frames_in']}, out {c['frames_out']}, bad {c['bad_frames']}, "
                f"echoes skipped {c['echoes']}, other nodes {c['other_nodes']}, send errors {c['send_errors']}, "
                f"watchdog trips {self.sim.watchdog_trips}, truth messages {self.truth_seq}, "
                f"physics steps {self.sim.steps}, missed ticks {c['missed_ticks']}, "
                f"skipped {self.sim.skipped_time:.3f} s")
