"""Gamepad profiles (services/console/gamepad_profile.py): teleop_twist_joy's keys in TOML, evdev names, validated
once with an error naming the bad key."""
from pathlib import Path

import pytest

from sharedctl.services.console.gamepad_profile import (
    ABS_CODES, BTN_CODES, DEFAULT_PROFILE, ProfileError, load_profile, parse_profile,
)

evdev = pytest.importorskip("evdev")

ROOT = Path(__file__).parents[2]

GOOD = """
enable_button = "BTN_TL"
axis_linear.x = "ABS_X"
scale_linear.x = 0.5
"""


def test_every_name_in_the_tables_is_the_kernels_code_as_python_evdev_has_it():
    for name, code in {**ABS_CODES, **BTN_CODES}.items():
        assert evdev.ecodes.ecodes[name] == code, name


def test_the_packaged_profile_is_an_xbox_layout_with_signs_for_evdevs_down_positive_y():
    profile = load_profile()
    axes = {a.key: (a.code, a.scale, a.scale_turbo) for a in profile.axes}
    assert axes == {"axis_linear.x": (0x00, 0.5, 1.0),         # ABS_X, right-positive
                    "axis_linear.y": (0x01, -0.5, -1.0),       # ABS_Y, down-positive: stick up = +y
                    "axis_angular.yaw": (0x03, -0.5, -1.0)}    # ABS_RX: stick left = counter-clockwise
    assert (profile.enable_button, profile.enable_turbo_button) == (0x136, 0x137)      # LB, RB
    assert (profile.estop_button, profile.clear_estop_button) == (0x131, 0x130)        # B, A
    assert (profile.take_control_button, profile.release_control_button) == (0x13b, 0x13a)   # Start, Back
    assert profile.require_enable_button and profile.deadzone == 0.08
    assert DEFAULT_PROFILE.name == "gamepad_xbox.toml"


def test_the_deploy_example_profile_loads():
    profile = load_profile(ROOT / "deploy" / "gamepad" / "dualsense.toml")
    assert profile.enable_button == 0x136 and profile.deadzone == 0.1


def test_names_codes_and_minus_one_bind_as_in_teleop_twist_joy():
    profile = parse_profile(GOOD + 'axis_linear.y = 1\nscale_linear.y = -0.5\nenable_turbo_button = -1\n'
                                   'estop_button = 305\n')
    assert [a.code for a in profile.axes] == [0, 1]
    assert profile.enable_turbo_button is None and profile.estop_button == 0x131
    assert profile.axes[0].scale_turbo == 0.5                 # no turbo scale given: the normal one


def test_without_require_enable_button_no_enable_button_is_needed():
    profile = parse_profile('require_enable_button = false\naxis_linear.x = "ABS_X"\nscale_linear.x = 0.5\n')
    assert not profile.require_enable_button and profile.enable_button is None


@pytest.mark.parametrize("text, key", [
    (GOOD + "enable_buton = 1\n", "enable_buton"),
    (GOOD + 'axis_linear.z = "ABS_Z"\n', "axis_linear.z"),
    (GOOD + 'axis_angular.pitch = "ABS_RY"\n', "axis_angular.pitch"),
    (GOOD.replace('"ABS_X"', '"ABS_FOO"'), "axis_linear.x"),
    (GOOD.replace('"ABS_X"', '"BTN_A"'), "axis_linear.x"),
    (GOOD.replace('"BTN_TL"', '"ABS_X"'), "enable_button"),
    (GOOD.replace('"BTN_TL"', "true"), "enable_button"),
    (GOOD.replace("0.5", "1.5"), "scale_linear.x"),
    (GOOD.replace("0.5", "inf"), "scale_linear.x"),
    (GOOD.replace("0.5", '"fast"'), "scale_linear.x"),
    (GOOD + "scale_linear_turbo.x = -1.0\n", "scale_linear_turbo.x"),
    (GOOD + 'axis_linear.y = "ABS_Y"\n', "scale_linear.y"),
    (GOOD + "scale_angular.yaw = 0.5\n", "scale_angular.yaw"),
    (GOOD + 'axis_angular.yaw = "ABS_X"\nscale_angular.yaw = 0.5\n', "axis_angular.yaw"),
    (GOOD.replace('enable_button = "BTN_TL"', ""), "enable_button"),
    (GOOD + 'estop_button = "BTN_TL"\n', "estop_button"),
    (GOOD + "deadzone = 1.2\n", "deadzone"),
    (GOOD + 'require_enable_button = "yes"\n', "require_enable_button"),
    ('enable_button = "BTN_TL"\naxis_linear = 3\n', "axis_linear"),
    ('enable_button = "BTN_TL"\n', "axis_linear"),
])
def test_a_bad_profile_is_a_profile_error_naming_the_key(text, key):
    with pytest.raises(ProfileError) as err:
        parse_profile(text, "pad.toml")
    assert f"pad.toml: {key}:" in str(err.value)


def test_bad_toml_and_a_missing_file_are_profile_errors_naming_the_file(tmp_path):
    with pytest.raises(ProfileError, match=r"pad.toml: not valid TOML"):
        parse_profile("enable_button = ", "pad.toml")
    with pytest.raises(ProfileError, match=r"nope.toml: cannot read"):
        load_profile(tmp_path / "nope.toml")
