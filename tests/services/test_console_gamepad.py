"""The gamepad state machine (services/console/gamepad.py), driven by recorded evdev streams
(tests/fixtures/gamepad/). Expected values are computed by hand from the drivers' absinfo:

xpad stick: min −32768, max 32767 → centre −0.5, half range 32767.5; the packaged profile's deadzone 0.08 →
flat 0.08 × 32767.5 = 2621.4 (xpad's own flat, 128, is smaller); beyond it n = (|raw + 0.5| − 2621.4) / 30146.1.
"""
import numpy as np
import pytest

from sharedctl.protocol.messages import ControlRequest
from sharedctl.services.console.gamepad import AbsInfo, AxisScale, DeviceInfo, Gamepad, GamepadError, Snapshot
from sharedctl.services.console.gamepad_profile import load_profile, parse_profile

pytest.importorskip("evdev")
from .gamepad_recording import POSE, ROOT_DEPLOY, after, replay

XBOX = load_profile()


def test_stick_noise_inside_the_flat_zone_reads_zero_even_with_the_deadman_held():
    _, frames = replay("xbox360_drive.jsonl", XBOX)
    rest = after(frames, "ABS_Y", -760)                    # x −410, y −760, yaw 2007: all within 2621.4
    assert not rest.command.deadman and np.all(rest.deflection == 0.0)
    held = after(frames, "BTN_TL", 1, nth=2)               # LB settled down; sticks still at rest
    assert held.command.deadman and np.all(held.deflection == 0.0)


def test_a_stick_pushed_up_deflects_y_by_the_normalised_value_times_the_scale():
    _, frames = replay("xbox360_drive.jsonl", XBOX)
    # ABS_Y −8000: n = −(7999.5 − 2621.4)/30146.1 = −0.178401; y = −0.5 × n
    assert after(frames, "ABS_Y", -8000).deflection == pytest.approx([0.0, 0.0892006, 0.0], abs=1e-6)
    # ABS_Y −17695: n = −(17694.5 − 2621.4)/30146.1 = −0.5000017; ABS_X 1510 is inside the zone
    half = after(frames, "ABS_Y", -17695)
    assert half.deflection == pytest.approx([0.0, 0.2500008, 0.0], abs=1e-6)
    assert half.command.q_d == pytest.approx(np.add(POSE, [0.0, 0.5 * 0.2500008, 0.0]), abs=1e-6)   # reach 0.5 m


def test_turbo_uses_the_turbo_scale_while_held():
    _, frames = replay("xbox360_drive.jsonl", XBOX)
    assert after(frames, "BTN_TR", 1).deflection == pytest.approx([0.0, 0.5000017, 0.0], abs=1e-6)  # −1.0 × n
    assert after(frames, "BTN_TR", 0).deflection == pytest.approx([0.0, 0.2500008, 0.0], abs=1e-6)


def test_full_travel_is_the_full_scale():
    _, frames = replay("xbox360_drive.jsonl", XBOX)
    assert after(frames, "ABS_X", 32767).deflection == pytest.approx([0.5, 0.5, 0.0])   # n = ±1 exactly


def test_letting_go_of_the_enable_button_stops_at_once_with_the_stick_still_pushed():
    _, frames = replay("xbox360_drive.jsonl", XBOX)
    i = frames.index(after(frames, "BTN_TL", 0, nth=2))
    before, release = frames[i - 1], frames[i]
    assert before.command.deadman and before.deflection == pytest.approx([0.5, 0.5, 0.0])
    assert not release.command.deadman and np.all(release.deflection == 0.0)
    assert release.command.q_d == POSE                      # the wish at the pose: no pull
    assert "stop" in release.actions                        # the console sends this command now


def test_a_bouncing_enable_contact_drops_the_deadman_for_its_open_report_only():
    _, frames = replay("xbox360_drive.jsonl", XBOX)
    closed, bounce, settled = after(frames, "BTN_TL", 1), after(frames, "BTN_TL", 0), after(frames, "BTN_TL", 1, nth=2)
    assert [closed.command.deadman, bounce.command.deadman, settled.command.deadman] == [True, False, True]
    assert bounce.actions == ["stop"]


def test_the_estop_button_latches_through_its_bounce_and_the_clear_button_clears_it():
    pad, frames = replay("xbox360_buttons.jsonl", XBOX)
    pressed = after(frames, "BTN_B", 1)
    assert pressed.command.estop and pressed.actions == ["estop"]
    assert all(f.command.estop for f in frames[frames.index(pressed):frames.index(after(frames, "BTN_A", 1))])
    assert sum(f.actions.count("estop") for f in frames) == 2          # the bounce closed the contact twice
    cleared = after(frames, "BTN_A", 1)
    assert not cleared.command.estop and cleared.actions == ["clear_estop"]
    assert not any(f.command.deadman for f in frames)                   # no enable: it never drives
    assert pad.counters.ignored == 1                                    # ABS_Z: not bound


def test_take_and_release_buttons_request_control_for_the_request_time():
    _, frames = replay("xbox360_buttons.jsonl", XBOX)
    take = after(frames, "BTN_START", 1)
    assert take.actions == ["take"] and take.command.control_request is ControlRequest.TAKE
    assert after(frames, "BTN_START", 0).command.control_request is ControlRequest.TAKE    # 80 ms later
    assert after(frames, "ABS_Z").command.control_request is ControlRequest.TAKE          # 190 ms later
    assert after(frames, "BTN_B", 1).command.control_request is ControlRequest.NONE      # 0.99 s > 0.5 s later
    release = after(frames, "BTN_SELECT", 1)
    assert release.actions == ["release"] and release.command.control_request is ControlRequest.RELEASE


def test_unplugged_mid_drive_the_next_command_is_hands_off():
    pad, frames = replay("xbox360_unplug.jsonl", XBOX)
    driving, unplugged = frames[-2], frames[-1]
    assert driving.command.deadman and driving.deflection == pytest.approx([0.5, 0.0, 0.0])
    assert not unplugged.command.deadman and np.all(unplugged.deflection == 0.0)
    assert unplugged.actions == ["stop"] and pad.status == "gamepad disconnected"


def test_after_syn_dropped_the_tail_is_ignored_and_the_state_read_back_decides():
    pad, frames = replay("xbox360_syn_dropped.jsonl", XBOX)
    driving = after(frames, "ABS_Y", -32768)
    assert driving.command.deadman and driving.deflection == pytest.approx([0.0, 0.5, 0.0])
    dropped = after(frames, "SYN_DROPPED")
    assert not dropped.command.deadman and np.all(dropped.deflection == 0.0) and "stop" in dropped.actions
    # LB's release was lost with the dropped events; the ioctls read back after the tail say LB is up
    resynced = frames[frames.index(dropped) + 1]
    assert not resynced.command.deadman and np.all(resynced.deflection == 0.0)
    assert pad.counters.dropped == 1 and pad.counters.resyncs == 1
    # LB again: y from the read-back ABS_Y −20000, n = −(19999.5 − 2621.4)/30146.1 = −0.5764626; x 410 in the zone
    again = frames[-1]
    assert again.command.deadman and again.deflection == pytest.approx([0.0, 0.2882313, 0.0], abs=1e-6)


def test_a_dualsense_is_normalised_from_its_own_absinfo():
    # hid-playstation: 0…255, no flat → centre 127.5, half 127.5; deadzone 0.1 → flat 12.75
    _, frames = replay("dualsense_drive.jsonl", load_profile(ROOT_DEPLOY / "dualsense.toml"))
    assert np.all(frames[1].deflection == 0.0)                       # rest noise 126 / 129
    part = after(frames, "ABS_Y", 64)       # y: n = −(63.5 − 12.75)/114.75 = −0.4422658; x 140: |12.5| < 12.75
    assert part.deflection == pytest.approx([0.0, 0.2211329, 0.0], abs=1e-6)
    assert after(frames, "ABS_Y", 0).deflection == pytest.approx([0.0, 1.0, 0.0])   # full, turbo −1.0
    assert not frames[-1].command.deadman and "stop" in frames[-1].actions


def test_a_pad_connected_with_the_enable_button_held_does_not_drive_until_it_is_pressed_again():
    _, frames = replay("xbox360_replug.jsonl", XBOX)
    assert not frames[0].command.deadman and not frames[1].command.deadman     # held at connect, stick up
    assert not after(frames, "BTN_TL", 0).command.deadman
    again = after(frames, "BTN_TL", 1)
    # ABS_Y −26010: n = −(26009.5 − 2621.4)/30146.1 = −0.7758250
    assert again.command.deadman and again.deflection == pytest.approx([0.0, 0.3879125, 0.0], abs=1e-6)


def test_without_require_enable_button_the_stick_drives_alone():
    profile = parse_profile('require_enable_button = false\naxis_linear.x = "ABS_X"\nscale_linear.x = 0.5\n')
    _, frames = replay("xbox360_unplug.jsonl", profile)
    assert frames[0].command.deadman
    # the default deadzone 0.05 → flat 1638.375; ABS_X 12000: n = (12000.5 − 1638.375)/31129.125 = 0.3328756; × 0.5
    assert after(frames, "ABS_X", 12000).deflection == pytest.approx([0.1664378, 0.0, 0.0], abs=1e-6)


def test_a_device_without_a_bound_axis_or_button_is_refused_naming_the_key():
    device = DeviceInfo("/dev/input/event3", "Generic USB Joystick", "usb-1/input0",
                        {0: AbsInfo(127, 0, 255), 1: AbsInfo(127, 0, 255)}, frozenset({0x120, 0x121, 0x136}))
    with pytest.raises(GamepadError, match=r"axis_angular.yaw: 'Generic USB Joystick'"):
        Gamepad(XBOX).connect(device, Snapshot({}), 0.0)
    flat_axis = DeviceInfo("/dev/input/event3", "Broken", "",
                           {0: AbsInfo(0, 5, 5), 1: AbsInfo(0, 0, 9), 3: AbsInfo(0, 0, 9)},
                           frozenset(XBOX.buttons().values()))
    with pytest.raises(GamepadError, match=r"axis_linear.x: 'Broken' reports the axis's range as 5…5"):
        Gamepad(XBOX).connect(flat_axis, Snapshot({}), 0.0)


def test_a_value_beyond_the_declared_range_is_full_scale_not_more():
    scale = AxisScale.of(AbsInfo(0, -32768, 32767, 16, 128), 0.08)
    assert scale.normalise(40000) == 1.0 and scale.normalise(-40000) == -1.0
