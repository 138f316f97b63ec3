"""CAN master for the three ODrive wheel axes (CANSimple, see protocol/README.md §1).

* Arming: Clear_Errors, Set_Controller_Mode (TORQUE_CONTROL, PASSTHROUGH), Set_Axis_State
  CLOSED_LOOP_CONTROL to every axis; armed when each axis has sent a Heartbeat in
  CLOSED_LOOP_CONTROL without error *after* the request; otherwise retried every
  `arm_timeout` seconds. While arming the caller keeps sending zero torque, which feeds the
  drives' watchdogs from the moment they close the loop.
* Keeping the mode: while running, `keep_torque_mode()` (called by the loop once a period) sends
  Set_Controller_Mode (TORQUE_CONTROL, PASSTHROUGH) to every axis again every `mode_repeat`
  seconds. A drive's heartbeat reports its axis state and errors but not its control mode: a drive
  whose Set_Controller_Mode was lost at arming (CAN loss) closes its loop in the mode it had —
  position control is ODrive's default — and then ignores every Set_Input_Torque while its
  heartbeat says all is well and the torque frames keep its watchdog fed, so its brake never
  engages either. The frame asks for the mode the drive should already be in (a no-op when it
  is); repeated, a lost one is mended within `mode_repeat` plus the bus's delay.
* Monitoring: Heartbeat state and error bits per axis (error changes → events), encoder
  estimates per axis (for odometry and the feedback age).
* Commands: Set_Input_Torque per axis, Estop to all axes, IDLE to all axes.
* Round trip: `probe_round_trip()`, called by the loop once a period, polls one axis at a time for
  Get_Bus_Voltage_Current (RTR) at `probe_rate`, and the reply's arrival gives the CAN round trip
  (round_trip.py: the largest of the last 20; `round_trip`, NaN until measured). One frame out and
  one back per probe (10 Hz by default); sending one never waits for its reply.
* Receive path: a frame the codec refuses is counted and skipped. A frame of the host's direction
  that commands a drive (Set_*, Estop, Clear_Errors; RTR polls only read) is either the echo of
  one this side sent — udp_multicast hands a socket its own frames back; SocketCAN does not — or
  another master's. Each frame sent is remembered, in order, with its wall time: an arrival that
  matches one sent less than `ECHO_WINDOW` before it (kernel receive time) is its echo and
  consumes it; anything else is **foreign** — counted by id (`foreign`), an Event naming the
  node, the command and the id, and `foreign_commands` for the daemon, which Estops. Nothing on
  CAN authenticates a sender: this detects a second master, a replayed capture or an intruder
  whose frames differ from this side's; it cannot stop one (docs/security.md).
* Frames go through a transport (services/can_transport/): on udp_multicast a socket of its own
  speaking python-can's datagrams, without python-can's per-frame `Message`; a python-can bus
  given here (or a stand-in with its `send`/`recv`) is wrapped in the generic transport.

Frames are built and read with `sharedctl.protocol.cansimple`; the two paths that run every
period use its per-period entry points, on the same compiled codecs: `torque_frame` packs
Set_Input_Torque, and `periodic_kind` picks out Get_Encoder_Estimates (read with
`encoder_estimates`) and the Set_Input_Torque echoes by the arbitration id first. They accept
exactly what `decode` accepts of those kinds; every other frame goes on to `decode`, which
decodes it or counts it as bad (tests/protocol/test_periodic_frames.py holds them to it).
"""
from __future__ import annotations

import math
import statistics
import time
from collections import Counter, deque
from dataclasses import dataclass, field

import can

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.canframe import DEFAULT_WHEEL_NODES
from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.odrive_enums import AxisState, ControlMode, InputMode, ODriveError

from ..can_transport import transport_for
from .encoder_check import EncoderCheck
from .odometry import AxisEstimate
from .round_trip import DEFAULT_RATE, PROBE_COMMAND, RoundTripProbe

PROBE_REPLY = cs.CLASS_BY_CMD[int(PROBE_COMMAND)]   # the Get_* frame a round-trip poll is answered with
ECHO_WINDOW = 0.25       # s: an echo arrives within this of its frame's send (loopback: microseconds)
SENT_REMEMBERED = 8192   # frames sent kept for echo matching (≈ 5 s of this side's frames)
ESTIMATE_INTERVALS = 9   # intervals between one axis's encoder frames kept for `estimate_interval`
HOST_FRAMES = (
    cs.Estop, cs.SetAxisState, cs.SetControllerMode, cs.SetInputVel, cs.SetInputTorque, cs.SetLimits,
    cs.ClearErrors, cs.PollRequest,
)   # the direction this side sends: echoes on udp_multicast, ignored


@dataclass
class AxisStatus:
    """What one drive last told us."""

    node_id: int
    state: AxisState | None = None
    error: ODriveError = ODriveError.NONE
    heartbeat_at: float = float("-inf")        # s, when the last heartbeat arrived
    estimate: AxisEstimate | None = None
    positions_rejected_in_a_row: int = 0
    estimate_frame_at: float | None = None      # s, arrival of the last encoder frame (accepted or not)
    estimate_intervals: deque = field(default_factory=lambda: deque(maxlen=ESTIMATE_INTERVALS))


@dataclass(frozen=True)
class CanEvent:
    """Something the master noticed, for the daemon to publish as an `Event`."""

    kind: str          # EventKind value: "fault", "watchdog_trip", "fault_cleared", "info"
    severity: str
    text: str


@dataclass
class CanMaster:
    bus: object                                  # a Transport, or a python-can bus (send, recv)
    nodes: tuple[int, ...] = DEFAULT_WHEEL_NODES
    arm_timeout: float = 0.5                     # s to see CLOSED_LOOP heartbeats before retrying
    mode_repeat: float = 0.1                     # s between Set_Controller_Mode repeats while running
    clock: object = time.monotonic
    wall_clock: object = time.time
    axes: dict = field(init=False)
    rx_frames: int = 0
    tx_frames: int = 0
    echoes_ignored: int = 0
    bad_frames: Counter = field(default_factory=Counter)
    encoder_check: EncoderCheck = field(default_factory=EncoderCheck)
    implausible_estimates: Counter = field(default_factory=Counter)   # values replaced, by reason
    tx_errors: Counter = field(default_factory=Counter)
    arm_attempts: int = 0
    arm_requested_at: float | None = None
    mode_sent_at: float = float("-inf")          # s, the last Set_Controller_Mode to every axis
    mode_repeats: int = 0
    events: list = field(default_factory=list)
    fast_paths: bool = True                      # the per-period frames through cansimple's entry points
    probe_rate: float = DEFAULT_RATE             # Hz, round-trip polls (0: none)
    foreign: Counter = field(default_factory=Counter)   # drive commands this side did not send, by arbitration id
    foreign_commands: int = 0
    last_foreign: str = ""                       # the last one, named

    def __post_init__(self) -> None:
        self.axes = {n: AxisStatus(n) for n in self.nodes}
        self.probe = RoundTripProbe(tuple(self.nodes), self.probe_rate)
        self.transport = transport_for(self.bus)
        self._node_ids = frozenset(self.nodes)
        self._sent: deque = deque(maxlen=SENT_REMEMBERED)   # (wall time, arbitration id, data) of frames sent

    def use_bus(self, bus) -> None:
        """Read and write another bus from now on."""
        self.bus, self.transport = bus, transport_for(bus)

    # ------------------------------------------------------------------ send
    def send(self, message) -> bool:
        frame = cs.encode(message)
        return self._send_frame(frame.arbitration_id, frame.data, frame.is_remote, frame.dlc)

    def _send_frame(self, arbitration_id: int, data: bytes, remote: bool = False, dlc: int | None = None) -> bool:
        try:
            self.transport.send(arbitration_id, remote, len(data) if dlc is None else dlc, data, timeout=0.01)
        except (can.CanError, OSError) as exc:
            self.tx_errors[type(exc).__name__] += 1
            return False
        self.tx_frames += 1
        if not remote:
            self._sent.append((self.wall_clock(), arbitration_id, data))
        return True

    def request_arming(self) -> None:
        """Clear errors, torque control + passthrough, closed loop: to every axis."""
        now = self.clock()
        for n in self.nodes:
            self.send(cs.ClearErrors(n))
            self.send(cs.SetControllerMode(n, ControlMode.TORQUE_CONTROL, InputMode.PASSTHROUGH))
            self.send(cs.SetAxisState(n, AxisState.CLOSED_LOOP_CONTROL))
        self.arm_requested_at = self.mode_sent_at = now
        self.arm_attempts += 1

    def keep_torque_mode(self, now: float) -> bool:
        """Set_Controller_Mode (TORQUE_CONTROL, PASSTHROUGH) to every axis again if `mode_repeat` has passed since
        the last (module doc); True if sent."""
        if now - self.mode_sent_at < self.mode_repeat:
            return False
        for n in self.nodes:
            self.send(cs.SetControllerMode(n, ControlMode.TORQUE_CONTROL, InputMode.PASSTHROUGH))
        self.mode_sent_at = now
        self.mode_repeats += 1
        return True

    def arming_done(self, now: float) -> bool:
        """True once every axis reported CLOSED_LOOP without error since the request; retries on timeout."""
        if self.arm_requested_at is None:
            self.request_arming()
            return False
        if all(self._armed(a) for a in self.axes.values()):
            return True
        if now - self.arm_requested_at > self.arm_timeout:
            missing = [n for n, a in self.axes.items() if not self._armed(a)]
            self.events.append(CanEvent(
                "fault", "warning",
                f"arming attempt {self.arm_attempts}: axes {missing} not in CLOSED_LOOP_CONTROL; retrying",
            ))
            self.request_arming()
        return False

    def _armed(self, axis: AxisStatus) -> bool:
        return (
            axis.heartbeat_at > self.arm_requested_at and axis.state is AxisState.CLOSED_LOOP_CONTROL
            and axis.error == ODriveError.NONE
        )

    def reset_arming(self) -> None:
        self.arm_requested_at = None

    def send_torques(self, torques) -> None:
        """Set_Input_Torque to every axis (a non-finite torque raises the codec's NonFiniteValue, as
        building the frame does)."""
        if not self.fast_paths:
            for n, tau in zip(self.nodes, torques):
                self.send(cs.SetInputTorque(n, float(tau)))
            return
        for n, tau in zip(self.nodes, torques):
            self._send_frame(*cs.torque_frame(n, float(tau)))

    def probe_round_trip(self) -> bool:
        """The round-trip poll that is due, if one is (round_trip.py); True if one was sent. Non-blocking: the
        reply is read by `receive_until` like any frame."""
        node = self.probe.due(self.clock())
        if node is None:
            return False
        at = self.clock()
        if not self.send(cs.PollRequest(node, PROBE_COMMAND)):
            return False                   # counted in `tx_errors`; the next probe is due a probe period later
        self.probe.probe_sent(node, at)
        return True

    @property
    def round_trip(self) -> float:
        """s, the CAN round trip estimate (round_trip.py); NaN until a probe has been answered."""
        return self.probe.round_trip

    def estop_all(self) -> None:
        for n in self.nodes:
            self.send(cs.Estop(n))

    def idle_all(self) -> None:
        for n in self.nodes:
            self.send(cs.SetAxisState(n, AxisState.IDLE))

    # --------------------------------------------------------------- receive
    def receive_until(self, deadline: float, max_frames: int = 2000, stop_when=None) -> int:
        """Read and handle frames until `deadline` (clock time), at most `max_frames`, or until `stop_when()` is
        true after a frame; returns how many were read."""
        count = 0
        while count < max_frames:
            remaining = deadline - self.clock()
            try:
                frame = self.transport.recv(max(remaining, 0.0))
            except (can.CanError, OSError, ValueError) as exc:
                self.bad_frames[type(exc).__name__] += 1
                frame = None
            if frame is None:
                if remaining <= 0:
                    return count
                continue
            count += 1
            self._handle(frame.arbitration_id, frame.is_remote, frame.is_extended, frame.dlc, frame.data,
                         self.arrival_time(frame.arrival), frame.arrival)
            if stop_when is not None and stop_when():
                return count
        return count

    def arrival_time(self, stamp: float | None) -> float:
        """When a frame reached the socket, on `clock`: the interface's receive timestamp `stamp` (wall
        clock, kernel-stamped on udp_multicast and SocketCAN) moved onto `clock`; now if it is implausible."""
        now = self.clock()
        lag = self.wall_clock() - (stamp or 0.0)
        return now - lag if 0.0 <= lag < 1.0 else now

    def handle(self, msg: can.Message, now: float) -> None:
        """One received python-can message, arrived at `now` (clock time)."""
        self._handle(msg.arbitration_id, msg.is_remote_frame, msg.is_extended_id, msg.dlc, bytes(msg.data), now)

    def _handle(self, arbitration_id: int, remote: bool, extended: bool, dlc: int, data: bytes, now: float,
                stamp: float | None = None) -> None:
        """One received frame (arrived at `now`, clock time; `stamp`, the interface's wall-clock receive time):
        decode; our own echoes are consumed, another master's commands reported; update the axes."""
        self.rx_frames += 1
        if self.fast_paths:
            kind = cs.periodic_kind(arbitration_id, dlc, data, remote, extended, self._node_ids)
            if kind is cs.SetInputTorque:
                self._host_frame(arbitration_id, data, stamp, kind)
                return
            if kind is cs.GetEncoderEstimates:
                pos, vel = cs.encoder_estimates(data)
                self._encoder(self.axes[arbitration_id >> 5], pos, vel, now)
                return
        try:
            frame = cs.decode(arbitration_id, data, remote, dlc=dlc, is_extended_id=extended, nodes=self.nodes)
        except ProtocolError as exc:
            self.bad_frames[type(exc).__name__] += 1
            return
        except Exception as exc:  # noqa: BLE001 — a bad frame never escapes the receive loop
            self.bad_frames[f"unexpected_{type(exc).__name__}"] += 1
            return
        if isinstance(frame, HOST_FRAMES):
            if remote or isinstance(frame, cs.PollRequest):
                self.echoes_ignored += 1         # a poll reads; whoever sent it commands nothing
            else:
                self._host_frame(arbitration_id, data, stamp, type(frame))
            return
        axis = self.axes[frame.node_id]
        if isinstance(frame, cs.GetEncoderEstimates):
            self._encoder(axis, frame.pos_estimate, frame.vel_estimate, now)
        elif isinstance(frame, cs.Heartbeat):
            self._heartbeat(axis, frame, now)
        elif type(frame) is PROBE_REPLY:
            self.probe.reply(frame.node_id, now)

    def _host_frame(self, arbitration_id: int, data: bytes, stamp: float | None, kind) -> None:
        """A drive command on the bus: the echo of one we sent (consumed, with any older ones whose echo never
        came), or another master's."""
        at = self.wall_clock() if stamp is None else stamp
        sent = self._sent
        while sent and sent[0][0] < at - ECHO_WINDOW:
            sent.popleft()                       # its echo never came (SocketCAN sends none)
        for i, (_, sent_id, sent_data) in enumerate(sent):
            if sent_id == arbitration_id and sent_data == data:
                for _ in range(i + 1):
                    sent.popleft()
                self.echoes_ignored += 1
                return
        self.foreign[arbitration_id] += 1
        self.foreign_commands += 1
        self.last_foreign = (f"{kind.__name__} to node {arbitration_id >> 5} (id 0x{arbitration_id:03X}), "
                             "not sent by this controller")
        if self.foreign[arbitration_id] == 1:
            self.events.append(CanEvent("fault", "critical", f"foreign CAN master: {self.last_foreign}"))

    def _encoder(self, axis: AxisStatus, pos: float, vel: float, now: float) -> None:
        if axis.estimate_frame_at is not None and now > axis.estimate_frame_at:
            axis.estimate_intervals.append(now - axis.estimate_frame_at)
        axis.estimate_frame_at = now
        before = axis.estimate
        axis.estimate, reason = self.encoder_check.judge(before, pos, vel, now, axis.positions_rejected_in_a_row)
        if before is not None and axis.estimate.epoch != before.epoch:
            self.events.append(CanEvent("fault", "error", f"axis {axis.node_id}: encoder jumped from "
                                        f"{before.pos_turns:.3f} to {pos:.3f} turns and stayed there (a drive "
                                        "restart?): a new origin, its travel over the gap taken from its speeds"))
        if reason is not None:
            self.implausible_estimates[reason] += 1
        axis.positions_rejected_in_a_row = axis.positions_rejected_in_a_row + 1 if reason else 0

    def _heartbeat(self, axis: AxisStatus, frame: cs.Heartbeat, now: float) -> None:
        error = ODriveError(frame.axis_error)
        if error != axis.error:
            new_bits = ODriveError(error & ~axis.error)
            if error == ODriveError.NONE:
                self.events.append(CanEvent("fault_cleared", "info", f"axis {axis.node_id}: errors cleared"))
            elif new_bits & ODriveError.WATCHDOG_TIMER_EXPIRED:
                self.events.append(CanEvent("watchdog_trip", "error",
                                            f"axis {axis.node_id}: watchdog expired ({_names(error)})"))
            elif new_bits:
                self.events.append(CanEvent("fault", "error", f"axis {axis.node_id}: {_names(error)}"))
        axis.error = error
        axis.state = frame.axis_state
        axis.heartbeat_at = now

    # ---------------------------------------------------------------- status
    def estimates(self) -> list:
        return [self.axes[n].estimate for n in self.nodes]

    def estimate_interval(self) -> float | None:
        """The drives' encoder period as received: the median of the recent intervals between one axis's
        frames, the slowest axis (None until every axis has sent two). A lost frame is one long interval."""
        medians = []
        for axis in self.axes.values():
            if not axis.estimate_intervals:
                return None
            medians.append(statistics.median(axis.estimate_intervals))
        return max(medians)

    def estimates_since(self, since: float) -> bool:
        """True when every axis has an estimate that arrived after `since` (clock time)."""
        for axis in self.axes.values():
            if axis.estimate is None or axis.estimate.received <= since:
                return False
        return True

    def heard_idle_since(self, since: float | None) -> bool:
        """True when every axis has sent, after `since` (clock time), a Heartbeat in a state other than
        CLOSED_LOOP_CONTROL and an encoder estimate: disarmed, and with a reading to start from."""
        return not self.not_idle(since)

    def not_idle(self, since: float | None = None) -> list[int]:
        """The axes not heard idle, with an encoder estimate, after `since` (None: ever)."""
        since = -math.inf if since is None else since
        return [
            n for n, a in self.axes.items()
            if a.heartbeat_at <= since or a.state is None or a.state is AxisState.CLOSED_LOOP_CONTROL
            or a.estimate is None or a.estimate.received <= since
        ]

    def faulted_axes(self) -> list[int]:
        """Axes that report an error or left closed loop (meaningful once armed)."""
        return [
            n for n, a in self.axes.items()
            if a.error != ODriveError.NONE or (a.state is not None and a.state is not AxisState.CLOSED_LOOP_CONTROL)
        ]

    def take_events(self) -> list:
        events, self.events = self.events, []
        return events

    @property
    def bad_frame_count(self) -> int:
        return sum(self.bad_frames.values())


def _names(error: ODriveError) -> str:
    names = [m.name for m in ODriveError if m.value and (error & m.value) == m.value and m.name]
    unknown = int(error) & ~sum(m.value for m in ODriveError)
    if unknown:
        names.append(f"0x{unknown:X}")
    return "|".join(names) or "NONE"
