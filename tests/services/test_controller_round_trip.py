"""The CAN round trip (services/controller/round_trip.py, can_master.py): RTR polls for Get_Bus_Voltage_Current,
one axis at a time at the configured rate, timed against their replies on an injected clock."""
import math

import can
import pytest

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.odrive_enums import AxisState, ODriveError
from sharedctl.services.controller.can_master import CanMaster
from sharedctl.services.controller.round_trip import RoundTripProbe


class RawBus:
    """send() records the python-can messages as they are; recv() must not be called (a probe never waits)."""

    def __init__(self):
        self.sent = []

    def send(self, msg, timeout=None):
        self.sent.append(msg)

    def recv(self, timeout=None):
        raise AssertionError("the probe read the bus")


class Clock:
    def __init__(self, t=100.0):
        self.t = t

    def __call__(self):
        return self.t


def message(frame):
    f = cs.encode(frame)
    return can.Message(arbitration_id=f.arbitration_id, data=f.data, is_remote_frame=f.is_remote, dlc=f.dlc,
                       is_extended_id=False)


def reply(node):
    return message(cs.GetBusVoltageCurrent(node, 24.0, 0.0))


def master_at(t=100.0, rate=10.0):
    return CanMaster(RawBus(), clock=Clock(t), probe_rate=rate)


def run_for(master, seconds, step=0.002, answer_after=None):
    """Call the probe every `step` s (a 500 Hz loop) for `seconds`; each poll answered `answer_after` s later."""
    pending = []
    end = master.clock.t + seconds
    while master.clock.t < end - 1e-9:
        for at, node in [p for p in pending if p[0] <= master.clock.t]:
            master.handle(reply(node), at)
            pending.remove((at, node))
        if master.probe_round_trip() and answer_after is not None:
            pending.append((master.clock.t + answer_after, master.bus.sent[-1].arbitration_id >> 5))
        master.clock.t += step


def test_polls_are_remote_frames_for_get_bus_voltage_current_one_axis_at_a_time():
    master = master_at()
    run_for(master, 0.35, answer_after=0.001)
    # id = node << 5 | 0x17 (Get_Bus_Voltage_Current), RTR, standard id, no data
    assert [(m.arbitration_id, m.is_remote_frame, m.is_extended_id, bytes(m.data)) for m in master.bus.sent] == \
        [(0x017, True, False, b""), (0x037, True, False, b""), (0x057, True, False, b""), (0x017, True, False, b"")]


def test_polls_go_out_at_the_configured_rate():
    for rate, expected in ((10.0, 20), (4.0, 8), (25.0, 50)):
        master = master_at(rate=rate)
        run_for(master, 2.0, answer_after=0.001)
        assert master.probe.sent == len(master.bus.sent) == expected, rate
        assert master.probe.replies == expected and master.probe.timeouts == 0, rate


def test_a_rate_of_zero_sends_no_poll():
    master = master_at(rate=0.0)
    run_for(master, 1.0)
    assert master.bus.sent == [] and master.probe.sent == 0 and math.isnan(master.round_trip)


def test_the_round_trip_is_nan_until_a_reply_arrives():
    master = master_at()
    assert math.isnan(master.round_trip)
    assert master.probe_round_trip()
    assert math.isnan(master.round_trip)


def test_the_round_trip_is_the_time_from_the_poll_to_its_replys_arrival():
    master = master_at(t=100.0)
    assert master.probe_round_trip()
    master.handle(reply(0), 100.0042)
    assert master.round_trip == pytest.approx(0.0042, abs=1e-12)
    assert (master.probe.sent, master.probe.replies, master.probe.timeouts) == (1, 1, 0)


def test_encoder_estimates_and_heartbeats_of_the_polled_axis_are_not_taken_for_its_reply():
    master = master_at(t=100.0)
    master.probe_round_trip()
    master.handle(message(cs.GetEncoderEstimates(0, 0.0, 0.0)), 100.001)
    master.handle(message(cs.Heartbeat(0, ODriveError.NONE, AxisState.IDLE)), 100.002)
    assert math.isnan(master.round_trip)
    master.handle(reply(0), 100.003)
    assert master.round_trip == pytest.approx(0.003, abs=1e-12)


def test_a_poll_unanswered_within_the_timeout_is_discarded_and_counted():
    master = master_at(t=100.0)
    master.probe_round_trip()                           # node 0 at 100.0; timeout 0.2 s
    master.clock.t = 100.15
    assert not master.probe_round_trip()                # still waiting: no second poll yet
    master.clock.t = 100.201
    assert master.probe_round_trip()                    # node 0's poll expired: node 1's goes out
    assert master.probe.timeouts == 1
    master.handle(reply(0), 100.21)                     # node 0's reply, too late: matches nothing
    assert math.isnan(master.round_trip) and master.probe.unmatched == 1
    master.handle(reply(1), 100.211)
    assert master.round_trip == pytest.approx(0.010, abs=1e-9)
    assert (master.probe.sent, master.probe.replies, master.probe.timeouts) == (2, 1, 1)


def test_a_reply_later_than_the_timeout_counts_as_a_timeout_even_before_the_poll_expired():
    master = master_at(t=100.0)
    master.probe_round_trip()
    master.handle(reply(0), 100.25)                     # read before the loop asked for another poll
    assert math.isnan(master.round_trip)
    assert (master.probe.replies, master.probe.timeouts, master.probe.unmatched) == (0, 1, 0)


def test_lost_polls_never_raise_the_rate_above_the_configured_one():
    master = master_at(rate=10.0)
    run_for(master, 3.0)                                # no drive answers
    assert 0 < master.probe.sent <= 30
    assert master.probe.timeouts == master.probe.sent - 1 and master.probe.replies == 0


def test_the_estimate_is_the_largest_of_the_last_20_round_trips():
    probe = RoundTripProbe((0, 1, 2), rate=10.0)
    t = 0.0
    measured = [0.050] + [0.001 * (k % 7 + 1) for k in range(20)]   # one slow trip, then 20 between 1 and 7 ms
    for k, rtt in enumerate(measured):
        node = probe.due(t)
        probe.probe_sent(node, t)
        probe.reply(node, t + rtt)
        if k < 20:
            assert probe.round_trip == pytest.approx(0.050)       # the slow trip is among the last 20
        t += 0.1
    assert probe.round_trip == pytest.approx(0.007)               # it has left the window


def test_the_simulated_drive_answers_the_poll_with_the_frame_the_master_times():
    """The drive side (services/robot/axis.py) of the chosen poll: the RTR the master sends, decoded as the robot
    decodes it, is answered with the frame that stops the master's timer."""
    from sharedctl.services.robot.axis import Axis

    master = master_at(t=100.0)
    master.probe_round_trip()
    sent = master.bus.sent[0]
    request = cs.decode(sent.arbitration_id, bytes(sent.data), sent.is_remote_frame, dlc=sent.dlc)
    answers = Axis(0).handle(request, 0.0)
    assert [type(a) for a in answers] == [cs.GetBusVoltageCurrent]
    master.handle(message(answers[0]), 100.0017)
    assert master.round_trip == pytest.approx(0.0017, abs=1e-12)
