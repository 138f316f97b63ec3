"""The controller's CAN master (services/controller/can_master.py) on an in-memory bus."""
import can
import pytest

from sharedctl.protocol import cansimple as cs
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
    for frame in (cs.SetInputTorque(0, 1.5), cs.Estop(1), cs.SetAxisState(2, AxisState.IDLE), cs.ClearErrors(0)):
        master.handle(message(frame), 1.0)
    master.handle(message(cs.PollRequest(0, cs.CommandId.GET_ERROR)), 1.0)
    assert master.echoes_ignored == 5
    assert all(a.state is None and a.estimate is None for a in master.axes.values())


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
    assert master.bus.sent == [cs.Estop(0), cs.Estop(1), cs.Estop(2)] + [cs.SetAxisState(n, AxisState.IDLE) for n in (0, 1, 2)]


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
