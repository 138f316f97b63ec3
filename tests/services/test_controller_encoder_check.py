"""A corrupted encoder value never reaches the odometry (services/controller/encoder_check.py)."""
import math
import struct

import pytest

from sharedctl.services.controller.encoder_check import EncoderCheck

CHECK = EncoderCheck()
PERIOD = 0.002


def _stream(vel=5.0, n=50, t0=0.0, p0=10.0):
    """A wheel turning at `vel` turns/s sampled every 2 ms: [(pos, vel, t)]."""
    return [(p0 + vel * k * PERIOD, vel, t0 + k * PERIOD) for k in range(n)]


def _run(frames):
    prev, rejected, reasons = None, 0, []
    for pos, vel, t in frames:
        prev, reason = CHECK.judge(prev, pos, vel, t, rejected)
        rejected = rejected + 1 if reason == "implausible_position" else 0
        reasons.append(reason)
    return prev, reasons


def _flip(value: float, bit: int) -> float:
    (raw,) = struct.unpack("<I", struct.pack("<f", value))
    return struct.unpack("<f", struct.pack("<I", raw ^ (1 << bit)))[0]


def test_a_consistent_stream_is_kept_as_it_is():
    last, reasons = _run(_stream())
    assert reasons == [None] * 50
    assert last.pos_turns == pytest.approx(10.0 + 5.0 * 49 * PERIOD)


@pytest.mark.parametrize("bit", range(12, 31))
def test_near_a_face_one_flipped_position_bit_is_caught_and_leaves_no_offset(bit):
    """At the low wheel speeds next to a face (0.1 turns/s) every plausible increment is close to 0."""
    frames = _stream(vel=0.1)
    pos, vel, t = frames[25]
    corrupted = _flip(pos, bit)
    frames[25] = (corrupted, vel, t)
    last, reasons = _run(frames)
    if abs(corrupted - pos) > 0.01:              # more than 2.5 mm of wheel travel
        assert reasons[25] == "implausible_position"
    assert reasons[26:] == [None] * 24
    assert last.pos_turns == pytest.approx(10.0 + 0.1 * 49 * PERIOD, abs=1e-9)


@pytest.mark.parametrize("bit", range(20, 31))
def test_a_flipped_velocity_bit_is_held_at_the_previous_speed(bit):
    frames = _stream()
    pos, vel, t = frames[25]
    frames[25] = (pos, _flip(vel, bit), t)
    prev, _ = _run(frames[:25])
    kept, reason = CHECK.judge(prev, *frames[25], 0)
    if not math.isfinite(frames[25][1]) or abs(frames[25][1] - vel) > CHECK.max_accel * PERIOD + CHECK.vel_slack:
        assert reason is not None and kept.vel_turns_s == vel
    assert math.isfinite(kept.vel_turns_s) and math.isfinite(kept.pos_turns)


def test_a_real_discontinuity_is_accepted_after_a_few_frames():
    frames = _stream(n=20) + [(0.0 + 5.0 * k * PERIOD, 5.0, (20 + k) * PERIOD) for k in range(10)]   # drive restarted
    last, reasons = _run(frames)
    assert reasons[20:24] == ["implausible_position"] * 4
    assert reasons[24] is None and last.pos_turns == pytest.approx(5.0 * 9 * PERIOD)


def test_a_late_frame_within_the_timing_slack_is_kept():
    frames = _stream(vel=8.0)
    pos, vel, t = frames[30]
    frames[30] = (pos, vel, t + 0.002)       # arrived 2 ms late: its value is from its send time
    _, reasons = _run(frames)
    assert reasons[30] is None


def test_a_sudden_real_acceleration_at_the_torque_limit_is_kept():
    frames, pos, vel = [], 10.0, 0.0
    for k in range(40):
        frames.append((pos, vel, k * PERIOD))
        new_vel = vel + 500.0 * PERIOD          # ~ the wheels' reach at 60 N·m
        pos += 0.5 * (vel + new_vel) * PERIOD
        vel = new_vel
    _, reasons = _run(frames)
    assert reasons == [None] * 40


def test_frames_after_a_gap_or_in_a_burst_are_not_judged_by_their_arrival_time():
    frames = _stream(vel=5.0)
    del frames[20:23]                                   # three frames lost: the next arrives 8 ms later
    pos, vel, t = frames[30]
    frames[30] = (pos, vel, frames[29][2] + 0.0001)     # released together with its predecessor
    _, reasons = _run(frames)
    assert reasons == [None] * len(frames)


def _braking_across_a_stall(stall=0.150):
    """A wheel braking from 7 turns/s at 20 turns/s², sampled every 2 ms; no frame arrives for `stall` s (a
    stalled host), then the stream goes on: [(pos, vel, t)]."""
    frames, pos, vel, t = [], 10.0, 7.0, 0.0
    while vel > 0.0:
        if not 0.05 < t < 0.05 + stall:
            frames.append((pos, vel, t))
        new_vel = max(vel - 20.0 * PERIOD, 0.0)
        pos, vel, t = pos + 0.5 * (vel + new_vel) * PERIOD, new_vel, t + PERIOD
    return frames


@pytest.mark.parametrize("stall", [0.06, 0.15, 0.25])
def test_a_wheel_that_turned_on_while_the_host_stalled_is_no_new_origin(stall):
    """Frames that stop for longer than the feedback timeout (the controller estops) and come back with the
    wheel's travel over the gap: that travel is the wheel's, not a drive restart — a new origin would make
    the controller refuse to arm again until restarted with --pose."""
    frames = _braking_across_a_stall(stall)
    assert frames[-1][2] > 0.05 + stall + 0.02          # the stream goes on after the stall
    last, reasons = _run(frames)
    assert reasons == [None] * len(frames)
    assert last.epoch == 0 and last.pos_turns == pytest.approx(frames[-1][0])


def test_after_a_stall_a_value_beyond_the_wheels_reach_is_still_dropped():
    frames = _braking_across_a_stall(0.15)
    after = next(i for i in range(1, len(frames)) if frames[i][2] - frames[i - 1][2] > 0.1)
    pos, vel, t = frames[after]
    frames[after] = (pos + 4.0, vel, t)       # 4 turns more than the wheel turned: more than 7 turns/s for 0.2 s
    last, reasons = _run(frames)
    assert reasons[after] == "implausible_position" and reasons[after + 1:] == [None] * (len(frames) - after - 1)
    assert last.epoch == 0 and last.pos_turns == pytest.approx(frames[-1][0])
