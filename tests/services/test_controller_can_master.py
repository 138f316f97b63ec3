"""The controller's CAN master (services/controller/can_master.py) on an in-memory bus."""
import math
import random
import struct

import can
import pytest

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.errors import NonFiniteValue
from sharedctl.protocol.odrive_enums import AxisState, ControlMode, InputMode, ODriveError
from sharedctl.services.controller.can_master import CanMaster


class MemoryBus:
    """send() records typed frames (decoded back with the codec); recv() pops queued messages."""

    def __init__(self):
        self.sent, self.queue = [], []

    def send(self, msg, timeout=None):
        self.sent.append(cs.decode(msg.arbitration_id, bytes(msg.data), msg.is_remote_frame, dlc=msg.dlc))

    def recv(self, timeout=None):
        return self.queue.pop(0) if self.queue else None


def message(frame):
    f = cs.encode(frame)
    return can.Message(arbitration_id=f.arbitration_id, data=f.data, is_remote_frame=f.is_remote, dlc=f.dlc,
                       is_extended_id=False)


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


@pytest.fixture
def master():
    return CanMaster(MemoryBus(), clock=Clock())


def test_arming_clears_errors_sets_torque_passthrough_then_closed_loop_on_every_axis(master):
    master.request_arming()
    for n in (0, 1, 2):
        frames = [f for f in master.bus.sent if f.node_id == n]
        assert frames == [
            cs.ClearErrors(n),
            cs.SetControllerMode(n, ControlMode.TORQUE_CONTROL, InputMode.PASSTHROUGH),
            cs.SetAxisState(n, AxisState.CLOSED_LOOP_CONTROL),
        ]


def test_the_torque_mode_is_asked_for_again_every_repeat_period_while_running(master):
    """A lost Set_Controller_Mode is invisible in the heartbeats (module doc): `keep_torque_mode` sends it to every
    axis again once `mode_repeat` has passed since the arming request or the last repeat, and not sooner."""
    master.request_arming()                                   # at 100.0
    master.bus.sent.clear()
    assert not master.keep_torque_mode(100.0 + 0.5 * master.mode_repeat) and master.bus.sent == []
    for k in (1, 2, 3):                                       # each a little after the last one's period
        assert master.keep_torque_mode(100.0 + k * (master.mode_repeat + 0.001))
        assert not master.keep_torque_mode(100.0 + k * (master.mode_repeat + 0.001) + 0.5 * master.mode_repeat)
    assert master.bus.sent == [cs.SetControllerMode(n, ControlMode.TORQUE_CONTROL, InputMode.PASSTHROUGH)
                               for _ in range(3) for n in (0, 1, 2)]
    assert master.mode_repeats == 3


def test_armed_only_after_closed_loop_heartbeats_newer_than_the_request(master):
    for n in (0, 1, 2):   # stale heartbeats from before the request do not count
        master.handle(message(cs.Heartbeat(n, ODriveError.NONE, AxisState.CLOSED_LOOP_CONTROL)), 99.0)
    master.request_arming()
    assert not master.arming_done(100.1)
    for n in (0, 1, 2):
        master.handle(message(cs.Heartbeat(n, ODriveError.NONE, AxisState.CLOSED_LOOP_CONTROL)), 100.2)
    assert master.arming_done(100.2)


def test_arming_is_retried_after_the_timeout(master):
    master.request_arming()
    master.clock.t = 100.6
    assert not master.arming_done(100.6)
    assert master.arm_attempts == 2
    assert sum(isinstance(f, cs.SetAxisState) for f in master.bus.sent) == 6
    assert [e.kind for e in master.take_events()] == ["fault"]


def test_own_command_frames_echoed_by_the_bus_are_ignored(master):
    own = (cs.SetInputTorque(0, 1.5), cs.Estop(1), cs.SetAxisState(2, AxisState.IDLE), cs.ClearErrors(0))
    for frame in own:
        master.send(frame)
    for frame in own:
        master.handle(message(frame), 1.0)
    master.handle(message(cs.PollRequest(0, cs.CommandId.GET_ERROR)), 1.0)   # a poll commands nothing
    assert master.echoes_ignored == 5 and master.foreign_commands == 0 and master.take_events() == []
    assert all(a.state is None and a.estimate is None for a in master.axes.values())


class WallClock:
    t = 1000.0

    def __call__(self):
        return self.t


@pytest.mark.parametrize("frame", [cs.SetInputTorque(1, 0.5), cs.SetAxisState(0, AxisState.CLOSED_LOOP_CONTROL),
                                   cs.ClearErrors(2), cs.Estop(1), cs.SetLimits(0, 5.0, 10.0),
                                   cs.SetInputVel(2, 1.0, 0.0)])
def test_a_drive_command_this_side_did_not_send_is_another_masters_and_named(master, frame):
    """What used to pass as this side's echo: a torque (or any command) frame nobody here sent."""
    master.send(cs.SetInputTorque(1, 0.25))                 # ours, with its echo below
    master.handle(message(cs.SetInputTorque(1, 0.25)), 1.0)
    master.handle(message(frame), 1.0)
    arbitration_id = cs.encode(frame).arbitration_id
    assert master.echoes_ignored == 1 and master.foreign_commands == 1 and master.foreign == {arbitration_id: 1}
    [event] = master.take_events()
    assert event.severity == "critical" and f"0x{arbitration_id:03X}" in event.text
    assert type(frame).__name__ in event.text and f"node {frame.node_id}" in event.text


def test_each_frame_sent_matches_one_echo_and_only_within_the_echo_window():
    wall = WallClock()
    master = CanMaster(MemoryBus(), clock=Clock(), wall_clock=wall)
    master.send(cs.SetInputTorque(0, 1.0))
    master._handle(*_fields(cs.SetInputTorque(0, 1.0)), 1.0, stamp=wall.t)
    master._handle(*_fields(cs.SetInputTorque(0, 1.0)), 1.0, stamp=wall.t)      # the same value once more
    assert (master.echoes_ignored, master.foreign_commands) == (1, 1)
    master.send(cs.SetInputTorque(0, 2.0))
    master._handle(*_fields(cs.SetInputTorque(0, 2.0)), 1.0, stamp=wall.t + 0.3)   # arrived 0.3 s after the send
    assert (master.echoes_ignored, master.foreign_commands) == (1, 2)
    # a lost echo does not stop the next from matching; the order of this side's frames is the bus's
    master.send(cs.SetInputTorque(0, 3.0))
    master.send(cs.SetInputTorque(1, 3.0))
    master._handle(*_fields(cs.SetInputTorque(1, 3.0)), 1.0, stamp=wall.t)
    assert (master.echoes_ignored, master.foreign_commands) == (2, 2)


def _fields(frame):
    f = cs.encode(frame)
    return f.arbitration_id, f.is_remote, False, f.dlc, f.data


def test_bad_frames_are_counted_and_skipped(master):
    bad = [
        can.Message(arbitration_id=0x009, data=b"\x00" * 4, is_extended_id=False),           # short encoder frame
        can.Message(arbitration_id=0x00A, data=b"", is_extended_id=False),                   # unknown command 0x0A
        can.Message(arbitration_id=0x1E9, data=b"\x00" * 8, is_extended_id=False),           # node 15: not ours
        can.Message(arbitration_id=0x009, data=b"\x00\x00\xc0\x7f" + b"\x00" * 4, is_extended_id=False),  # NaN
        can.Message(arbitration_id=0x12345, data=b"", is_extended_id=True),
    ]
    for msg in bad:
        master.handle(msg, 1.0)
    assert master.bad_frame_count == 5
    assert set(master.bad_frames) == {"BadLength", "UnknownCommand", "BadNodeId", "NonFiniteValue", "BadArbitrationId"}


def test_encoder_estimates_are_kept_per_axis_with_their_arrival_time(master):
    master.handle(message(cs.GetEncoderEstimates(1, 2.5, -0.75)), 3.25)
    est = master.estimates()
    assert est[0] is None and est[2] is None
    assert (est[1].pos_turns, est[1].vel_turns_s, est[1].received) == (2.5, -0.75, 3.25)


def test_watchdog_error_in_a_heartbeat_raises_an_event_and_marks_the_axis_faulted(master):
    master.handle(message(cs.Heartbeat(2, ODriveError.WATCHDOG_TIMER_EXPIRED, AxisState.IDLE)), 1.0)
    events = master.take_events()
    assert [e.kind for e in events] == ["watchdog_trip"] and "WATCHDOG_TIMER_EXPIRED" in events[0].text
    assert master.faulted_axes() == [2]
    master.handle(message(cs.Heartbeat(2, ODriveError.NONE, AxisState.CLOSED_LOOP_CONTROL)), 1.1)
    assert [e.kind for e in master.take_events()] == ["fault_cleared"]
    assert master.faulted_axes() == []


def test_estop_and_idle_go_to_every_axis(master):
    master.estop_all()
    master.idle_all()
    assert master.bus.sent == ([cs.Estop(0), cs.Estop(1), cs.Estop(2)]
                               + [cs.SetAxisState(n, AxisState.IDLE) for n in (0, 1, 2)])


def test_send_errors_are_counted_not_raised():
    class FailingBus(MemoryBus):
        def send(self, msg, timeout=None):
            raise can.CanOperationError("bus down")
    master = CanMaster(FailingBus())
    master.send_torques([0.0, 0.0, 0.0])
    assert master.tx_errors["CanOperationError"] == 3 and master.tx_frames == 0


def test_arrival_time_uses_the_interface_receive_timestamp():
    """A frame's arrival is the interface's receive stamp (wall clock) moved onto the master's clock."""
    bus = MemoryBus()
    master = CanMaster(bus, clock=lambda: 50.0, wall_clock=lambda: 1000.0)
    for stamp, arrival in ((999.996, 49.996),     # stamped 4 ms before we read it
                           (0.0, 50.0),           # no timestamp: the time it was read
                           (1000.5, 50.0)):       # from the future (clock mismatch): the time it was read
        msg = message(cs.GetEncoderEstimates(0, 0.0, 0.0))
        msg.timestamp = stamp
        bus.queue.append(msg)
        assert master.receive_until(0.0) == 1
        assert master.axes[0].estimate_frame_at == pytest.approx(arrival)


def test_the_drives_encoder_period_is_the_median_interval_of_the_slowest_axis(master):
    assert master.estimate_interval() is None
    for k in range(6):
        for n in (0, 1, 2):
            if not (n == 2 and k == 3):            # one frame of axis 2 lost: one long interval
                master.handle(message(cs.GetEncoderEstimates(n, 0.0, 0.0)), 1.0 + 0.002 * k + 1e-5 * n)
    assert master.estimate_interval() == pytest.approx(0.002, abs=1e-9)
    assert master.estimates_since(1.0095) and not master.estimates_since(1.0101)


def test_receive_until_stops_as_soon_as_its_condition_holds(master):
    for n in (0, 1, 2):
        master.bus.queue.append(message(cs.GetEncoderEstimates(n, 0.0, 0.0)))
    master.bus.queue.append(message(cs.Heartbeat(0, ODriveError.NONE, AxisState.IDLE)))
    read = master.receive_until(master.clock() + 1.0, stop_when=lambda: master.estimates_since(0.0))
    assert read == 3 and len(master.bus.queue) == 1


# --- the per-period frames (cansimple.torque_frame / periodic_kind) against the general codec path ------

class RawBus:
    """send() records the python-can messages as they are; recv() has nothing."""

    def __init__(self):
        self.sent = []

    def send(self, msg, timeout=None):
        self.sent.append(msg)

    def recv(self, timeout=None):
        return None


@pytest.mark.parametrize("torque", [0.0, -0.0, 1.5, -59.99, 1e-30, 3.0e38, 0.1])
def test_torque_frames_are_the_codecs_bytes_and_id(torque):
    master = CanMaster(RawBus())
    master.send_torques([torque, torque, torque])
    expected = [cs.encode(cs.SetInputTorque(n, torque)) for n in (0, 1, 2)]
    assert [(m.arbitration_id, bytes(m.data), m.dlc, m.is_remote_frame, m.is_extended_id) for m in master.bus.sent] == \
        [(f.arbitration_id, f.data, f.dlc, False, False) for f in expected]


def test_a_non_finite_torque_raises_the_codecs_error_and_sends_nothing():
    master = CanMaster(RawBus())
    with pytest.raises(NonFiniteValue):
        master.send_torques([math.nan, 0.0, 0.0])
    assert master.bus.sent == []


def test_an_echo_of_our_own_torque_frame_is_counted_and_not_decoded():
    master = CanMaster(RawBus())
    master.send_torques([0.0, 2.5, 0.0])
    master.handle(message(cs.SetInputTorque(1, 2.5)), 1.0)
    assert master.echoes_ignored == 1 and master.bad_frame_count == 0 and master.rx_frames == 1
    assert master.foreign_commands == 0


def test_encoder_estimates_reach_the_axes_through_the_per_period_path():
    master = CanMaster(RawBus())
    master.handle(message(cs.GetEncoderEstimates(2, 1.25, -0.5)), 3.0)
    estimate = master.axes[2].estimate
    assert (estimate.pos_turns, estimate.vel_turns_s, estimate.received) == (1.25, -0.5, 3.0)


def test_a_torque_echo_or_an_estimate_with_a_non_finite_value_is_still_a_bad_frame():
    master = CanMaster(RawBus())
    nan = struct.pack("<f", math.nan) + bytes(4)
    master.handle(can.Message(arbitration_id=(1 << 5) | 0x0E, data=nan, dlc=8, is_extended_id=False), 1.0)
    master.handle(can.Message(arbitration_id=(1 << 5) | 0x09, data=nan, dlc=8, is_extended_id=False), 1.0)
    assert master.bad_frames == {"NonFiniteValue": 2} and master.echoes_ignored == 0 and master.axes[1].estimate is None


def random_frames(n, seed):
    """Frames the codec accepts and refuses: every command id, nodes in and out of range, wrong DLCs,
    RTR and extended ids, NaN/inf payloads, and plausible estimates."""
    rng = random.Random(seed)
    specials = [math.nan, math.inf, -math.inf, 0.0, 1e-40, 3.4e38]
    t = 0.0
    for _ in range(n):
        t += 0.0005
        node = rng.choice([0, 1, 2, 2, 1, 0, 3, 63])
        cmd = rng.choice([0x09, 0x09, 0x09, 0x0E, 0x0E, 0x0E, 0x01, 0x02, 0x07, 0x0B, 0x0D, 0x18, 0x1F, 0x05])
        if rng.random() < 0.15:
            values = [rng.choice(specials), rng.uniform(-5, 5)]
        else:
            values = [rng.uniform(-0.01, 0.01) + t * 2.0, 2.0 + rng.uniform(-0.2, 0.2)]
        data = struct.pack("<ff", *values)
        if rng.random() < 0.1:
            data = data[: rng.randrange(0, 8)]
        remote = rng.random() < 0.05
        extended = rng.random() < 0.05
        arb = (node << 5) | cmd
        yield t, can.Message(arbitration_id=arb, data=b"" if remote else data, dlc=8 if remote else len(data),
                             is_remote_frame=remote, is_extended_id=extended, check=False)
        if rng.random() < 0.05:
            yield t, message(cs.Heartbeat(rng.choice((0, 1, 2)), ODriveError.NONE, AxisState.CLOSED_LOOP_CONTROL))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_per_period_path_and_the_codec_path_agree_on_every_frame(seed):
    """Counters (received, echoes, bad frames by error type, implausible estimates) and every axis's
    estimate are the same with and without the per-period entry points."""
    fast, codec = CanMaster(RawBus()), CanMaster(RawBus(), fast_paths=False)
    for t, msg in random_frames(3000, seed):
        fast.handle(msg, t)
        codec.handle(msg, t)
        assert [fast.axes[n].estimate for n in (0, 1, 2)] == [codec.axes[n].estimate for n in (0, 1, 2)]
    assert fast.rx_frames == codec.rx_frames
    assert fast.echoes_ignored == codec.echoes_ignored and fast.foreign == codec.foreign
    assert fast.echoes_ignored + fast.foreign_commands > 100
    assert fast.bad_frames == codec.bad_frames and sum(fast.bad_frames.values()) > 100
    assert fast.implausible_estimates == codec.implausible_estimates
    assert [fast.axes[n].positions_rejected_in_a_row for n in (0, 1, 2)] == \
        [codec.axes[n].positions_rejected_in_a_row for n in (0, 1, 2)]


def test_odd_python_can_fields_never_escape_the_receive_path():
    master = CanMaster(RawBus())
    odd = can.Message(arbitration_id=0x0E, data=b"12345678", dlc=8, is_extended_id=False, check=False)
    odd.arbitration_id = 14.0                       # not an int
    master.handle(odd, 1.0)
    odd2 = can.Message(arbitration_id=0x09, data=b"12345678", dlc=8, is_extended_id=False, check=False)
    odd2.dlc = True
    master.handle(odd2, 1.0)
    assert master.bad_frame_count == 2 and master.echoes_ignored == 0


def test_a_transport_is_used_as_it_is_and_a_python_can_bus_is_wrapped():
    from sharedctl.services.can_transport import PythonCanTransport, Transport

    class Loop(Transport):
        def __init__(self):
            self.sent = []

        def send(self, arbitration_id, is_remote, dlc, data, timeout=None):
            self.sent.append((arbitration_id, data))

        def recv(self, timeout):
            return None

        def fileno(self):
            return -1

        def shutdown(self):
            pass

    transport = Loop()
    master = CanMaster(transport)
    master.send_torques([1.5, 0.0, 0.0])
    assert master.transport is transport
    assert transport.sent == [(0x00E, bytes.fromhex("0000c03f00000000")), (0x02E, bytes(8)), (0x04E, bytes(8))]
    assert isinstance(CanMaster(RawBus()).transport, PythonCanTransport)
