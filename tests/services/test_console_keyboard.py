"""The keyboard virtual joystick: key parsing, spring return, deadman, estop, control requests."""
import numpy as np
import pytest

from sharedctl.protocol.messages import ControlRequest
from sharedctl.services.console.keyboard import VirtualJoystick, parse_keys


def test_arrow_escape_sequences_parse_to_arrow_names():
    assert parse_keys("\x1b[A\x1b[B\x1b[C\x1b[D") == ["up", "down", "right", "left"]


def test_lone_escape_is_esc_and_space_is_space():
    assert parse_keys("\x1b x") == ["esc", "space", "x"]


def test_letters_are_lower_cased_and_unknown_escapes_skipped():
    assert parse_keys("W\x1b[1;5Ca") == ["w", "a"]


def test_a_press_deflects_its_axis_by_one_step():
    stick = VirtualJoystick()
    stick.press("right", 0.0)
    stick.press("w", 0.0)
    stick.press("q", 0.0)
    assert np.allclose(stick.deflection(0.0), [0.5, 0.5, 0.5])


def test_deflection_saturates_at_full_scale():
    stick = VirtualJoystick()
    for _ in range(5):
        stick.press("left", 0.0)
    assert stick.deflection(0.0)[0] == -1.0


def test_the_handle_holds_briefly_then_springs_back_to_centre_within_return_time():
    stick = VirtualJoystick(step=1.0, hold=0.05, return_time=0.3)
    stick.press("up", 0.0)
    assert stick.deflection(0.05)[1] == pytest.approx(1.0)
    assert stick.deflection(0.20)[1] == pytest.approx(0.5)
    assert stick.deflection(0.35)[1] == pytest.approx(0.0)
    assert stick.deflection(1.0)[1] == 0.0


def test_repeated_presses_keep_a_held_key_deflected():
    stick = VirtualJoystick(step=1.0, hold=0.06, return_time=0.3)
    for k in range(30):                     # key repeat at 30 Hz for 1 s
        stick.press("d", k / 30)
    assert stick.deflection(1.0)[0] > 0.9


def test_space_toggles_the_deadman():
    stick = VirtualJoystick(deadman_mode="toggle")
    assert not stick.deadman(0.0)
    stick.press("space", 0.0)
    assert stick.deadman(5.0)
    stick.press("space", 5.0)
    assert not stick.deadman(5.1)


def test_in_hold_mode_the_deadman_drops_when_space_stops_repeating():
    stick = VirtualJoystick(deadman_mode="hold", deadman_hold=0.6)
    stick.press("space", 1.0)
    assert stick.deadman(1.5)
    assert not stick.deadman(1.7)


def test_x_and_esc_request_an_estop_and_c_clears_it():
    stick = VirtualJoystick()
    stick.press("x", 0.0)
    assert stick.estop
    stick.press("c", 0.1)
    assert not stick.estop
    stick.press("esc", 0.2)
    assert stick.estop


def test_take_and_release_are_requested_for_request_time_then_none():
    stick = VirtualJoystick(request_time=0.5)
    stick.press("t", 0.0)
    assert stick.control_request(0.4) is ControlRequest.TAKE
    assert stick.control_request(0.6) is ControlRequest.NONE
    stick.press("r", 1.0)
    assert stick.control_request(1.1) is ControlRequest.RELEASE


def test_the_wish_is_the_pose_offset_by_reach_times_deflection():
    stick = VirtualJoystick(reach=np.array([0.5, 0.5, 0.5]))
    stick.press("right", 0.0)
    assert np.allclose(stick.wish(np.array([1.0, 2.0, 0.1]), 0.0), [1.25, 2.0, 0.1])


def test_the_deadman_holds_by_default_and_drops_when_space_stops_repeating():
    """Threat: a toggled deadman latches, so an operator who lets go leaves it on (docs/security.md). The console's
    default, from the joystick to the command line and the site config, holds it only while space repeats."""
    import tomllib
    from pathlib import Path

    from sharedctl.services.console.app import ConsoleOptions
    from sharedctl.services.cli import build_parser

    stick = VirtualJoystick()
    stick.press("space", 1.0)
    assert stick.deadman(1.0 + 0.66) and not stick.deadman(1.0 + 0.75)
    assert ConsoleOptions.__dataclass_fields__["deadman_mode"].default == "hold"
    assert build_parser().parse_args(["console"]).deadman == "hold"
    site = tomllib.loads((Path(__file__).parents[2] / "deploy" / "config" / "console.toml").read_text())
    assert site.get("deadman", site.get("console", {}).get("deadman")) == "hold"
