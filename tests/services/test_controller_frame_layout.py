"""The per-period CAN frames read and written by their layout (services/controller/frame_layout.py):
exactly what the codec (sharedctl.protocol.cansimple) would make of them, frame for frame."""
import math
import random
import struct

import can
import pytest

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.errors import NonFiniteValue, OutOfRange
from sharedctl.protocol.odrive_enums import AxisState, ODriveError
from sharedctl.services.controller import frame_layout
from sharedctl.services.controller.can_master import CanMaster

NODES = (0, 1, 2)


class MemoryBus:
    def __init__(self):
        self.sent = []

    def send(self, msg, timeout=None):
        self.sent.append(msg)

    def recv(self, timeout=None):
        return None


def message(frame):
    f = cs.encode(frame)
    return can.Message(arbitration_id=f.arbitration_id, data=f.data, is_remote_frame=f.is_remote, dlc=f.dlc,
                       is_extended_id=False)


@pytest.mark.parametrize("torque", [0.0, -0.0, 1.5, -59.99, 1e-30, 3.0e38, 0.1])
def test_torque_frames_are_the_codecs_bytes_and_id(torque):
    master = CanMaster(MemoryBus())
    master.send_torques([torque, torque, torque])
    expected = [cs.encode(cs.SetInputTorque(n, torque)) for n in NODES]
    assert [(m.arbitration_id, bytes(m.data), m.dlc, m.is_remote_frame, m.is_extended_id) for m in master.bus.sent] == \
        [(f.arbitration_id, f.data, f.dlc, False, False) for f in expected]


@pytest.mark.parametrize("bad, error", [(math.nan, NonFiniteValue), (math.inf, NonFiniteValue), (1e39, OutOfRange)])
def test_a_torque_the_codec_refuses_raises_the_codecs_error(bad, error):
    with pytest.raises(error):
        frame_layout.torque_data(bad)
    with pytest.raises(error):
        cs.SetInputTorque(0, bad)


def test_an_echo_of_our_own_torque_frame_is_counted_and_not_decoded():
    master = CanMaster(MemoryBus())
    master.handle(message(cs.SetInputTorque(1, 2.5)), 1.0)
    assert master.echoes_ignored == 1 and master.bad_frame_count == 0 and master.rx_frames == 1


def test_encoder_estimates_still_reach_the_axes_through_the_layout():
    master = CanMaster(MemoryBus())
    master.handle(message(cs.GetEncoderEstimates(2, 1.25, -0.5)), 3.0)
    estimate = master.axes[2].estimate
    assert (estimate.pos_turns, estimate.vel_turns_s, estimate.received) == (1.25, -0.5, 3.0)


def test_a_torque_echo_with_a_non_finite_value_is_still_a_bad_frame():
    master = CanMaster(MemoryBus())
    nan = struct.pack("<f", math.nan) + bytes(4)
    master.handle(can.Message(arbitration_id=(1 << 5) | 0x0E, data=nan, dlc=8, is_extended_id=False), 1.0)
    master.handle(can.Message(arbitration_id=(1 << 5) | 0x09, data=nan + b"", dlc=8, is_extended_id=False), 1.0)
    assert master.bad_frame_count == 2 and master.echoes_ignored == 0 and master.axes[1].estimate is None


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
            yield t, message(cs.Heartbeat(rng.choice(NODES), ODriveError.NONE, AxisState.CLOSED_LOOP_CONTROL))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_layout_path_and_the_codec_path_agree_on_every_frame(seed):
    """Counters (received, echoes, bad frames by error type, implausible estimates) and every axis's
    estimate are the same with and without the layout path."""
    fast, codec = CanMaster(MemoryBus()), CanMaster(MemoryBus(), fast_paths=False)
    for t, msg in random_frames(3000, seed):
        fast.handle(msg, t)
        codec.handle(msg, t)
        assert [fast.axes[n].estimate for n in NODES] == [codec.axes[n].estimate for n in NODES]
    assert fast.rx_frames == codec.rx_frames
    assert fast.echoes_ignored == codec.echoes_ignored > 100
    assert fast.bad_frames == codec.bad_frames and sum(fast.bad_frames.values()) > 100
    assert fast.implausible_estimates == codec.implausible_estimates
    assert [fast.axes[n].positions_rejected_in_a_row for n in NODES] == \
        [codec.axes[n].positions_rejected_in_a_row for n in NODES]


def test_odd_python_can_fields_never_escape_the_receive_path():
    master = CanMaster(MemoryBus())
    odd = can.Message(arbitration_id=0x0E, data=b"12345678", dlc=8, is_extended_id=False, check=False)
    odd.arbitration_id = 14.0                       # not an int
    master.handle(odd, 1.0)
    odd2 = can.Message(arbitration_id=0x09, data=b"12345678", dlc=8, is_extended_id=False, check=False)
    odd2.dlc = True
    master.handle(odd2, 1.0)
    assert master.bad_frame_count == 2 and master.echoes_ignored == 0
