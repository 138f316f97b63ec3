"""A gamepad profile: which evdev axis drives which degree of freedom, at what scale, and which
buttons enable, turbo, estop and take control. Data, validated once at start (`load_profile`).

The keys are teleop_twist_joy's (ROS), written as TOML dotted keys, with evdev names for the
axes and buttons instead of joy indices:

    require_enable_button = true        # the deadman: no motion unless enable (or turbo) is held
    enable_button = "BTN_TL"            # held: normal scales
    enable_turbo_button = "BTN_TR"      # held: turbo scales (enables on its own, as in teleop_twist_joy)
    axis_linear.x = "ABS_X"             # axis → x, y (m) and yaw (rad) of the wish
    axis_linear.y = "ABS_Y"
    axis_angular.yaw = "ABS_RX"
    scale_linear.x = 0.5                # deflection at full stick (the wire's range is [−1, 1]);
    scale_linear.y = -0.5               # the sign turns the axis (evdev's ABS_Y is down-positive)
    scale_linear_turbo.x = 1.0          # default: the normal scale
    deadzone = 0.05                     # of the half range, beyond the device's own flat (ROS joy's)
    estop_button = "BTN_EAST"           # a press latches an estop request …
    clear_estop_button = "BTN_SOUTH"    # … until this one
    take_control_button = "BTN_START"   # a press asks for the operator lease, like the console's T
    release_control_button = "BTN_SELECT"

An axis or button is an evdev name (`ABS_*`, `BTN_*`; the kernel's aliases such as BTN_A =
BTN_SOUTH are accepted) or its integer code; -1 (teleop_twist_joy's "none") or leaving the key
out means no such binding. Anything else — an unknown key, a name that is not an axis or button,
a scale outside [−1, 1] or a turbo scale of the other sign, one button bound twice — is a
`ProfileError` naming the key. Whether the device has what the profile names is checked when
it is opened (gamepad.py).
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

DEFAULT_PROFILE = Path(__file__).with_name("gamepad_xbox.toml")   # packaged: an Xbox-style pad (xpad)

DOFS = ("x", "y", "yaw")   # the wish's coordinates, in the order of the wire's joystick vector

# linux/input-event-codes.h: the absolute axes and the buttons of joysticks and gamepads (the ABI; a
# test checks every entry against python-evdev's `ecodes`). Other codes may be given as integers.
ABS_CODES = {
    "ABS_X": 0x00, "ABS_Y": 0x01, "ABS_Z": 0x02, "ABS_RX": 0x03, "ABS_RY": 0x04, "ABS_RZ": 0x05,
    "ABS_THROTTLE": 0x06, "ABS_RUDDER": 0x07, "ABS_WHEEL": 0x08, "ABS_GAS": 0x09, "ABS_BRAKE": 0x0a,
    "ABS_HAT0X": 0x10, "ABS_HAT0Y": 0x11, "ABS_HAT1X": 0x12, "ABS_HAT1Y": 0x13,
    "ABS_HAT2X": 0x14, "ABS_HAT2Y": 0x15, "ABS_HAT3X": 0x16, "ABS_HAT3Y": 0x17, "ABS_MISC": 0x28,
}
BTN_CODES = {
    "BTN_TRIGGER": 0x120, "BTN_THUMB": 0x121, "BTN_THUMB2": 0x122, "BTN_TOP": 0x123, "BTN_TOP2": 0x124,
    "BTN_PINKIE": 0x125, "BTN_BASE": 0x126, "BTN_BASE2": 0x127, "BTN_BASE3": 0x128, "BTN_BASE4": 0x129,
    "BTN_BASE5": 0x12a, "BTN_BASE6": 0x12b, "BTN_DEAD": 0x12f,
    "BTN_SOUTH": 0x130, "BTN_A": 0x130, "BTN_EAST": 0x131, "BTN_B": 0x131, "BTN_C": 0x132,
    "BTN_NORTH": 0x133, "BTN_X": 0x133, "BTN_WEST": 0x134, "BTN_Y": 0x134, "BTN_Z": 0x135,
    "BTN_TL": 0x136, "BTN_TR": 0x137, "BTN_TL2": 0x138, "BTN_TR2": 0x139, "BTN_SELECT": 0x13a,
    "BTN_START": 0x13b, "BTN_MODE": 0x13c, "BTN_THUMBL": 0x13d, "BTN_THUMBR": 0x13e,
    "BTN_DPAD_UP": 0x220, "BTN_DPAD_DOWN": 0x221, "BTN_DPAD_LEFT": 0x222, "BTN_DPAD_RIGHT": 0x223,
    **{f"BTN_TRIGGER_HAPPY{i}": 0x2c0 + i - 1 for i in range(1, 41)},
}
ABS_MAX, KEY_MAX = 0x3f, 0x2ff

BUTTON_KEYS = ("enable_button", "enable_turbo_button", "estop_button", "clear_estop_button",
               "take_control_button", "release_control_button")
_AXIS_KEYS = {"axis_linear": ("x", "y"), "axis_angular": ("yaw",)}
_SCALE_KEYS = {"scale_linear": ("x", "y"), "scale_linear_turbo": ("x", "y"),
               "scale_angular": ("yaw",), "scale_angular_turbo": ("yaw",)}
_TOP_KEYS = {"require_enable_button", "deadzone", *BUTTON_KEYS, *_AXIS_KEYS, *_SCALE_KEYS}


class ProfileError(ValueError):
    """A gamepad profile that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class AxisBinding:
    """One evdev axis driving one degree of freedom of the wish."""

    dof: int              # index into DOFS
    key: str              # the profile's key, e.g. "axis_linear.y"
    code: int             # EV_ABS code
    scale: float          # deflection at full stick, normal
    scale_turbo: float    # deflection at full stick, turbo


@dataclass(frozen=True)
class GamepadProfile:
    axes: tuple[AxisBinding, ...]
    require_enable_button: bool = True
    enable_button: int | None = None
    enable_turbo_button: int | None = None
    estop_button: int | None = None
    clear_estop_button: int | None = None
    take_control_button: int | None = None
    release_control_button: int | None = None
    deadzone: float = 0.05          # fraction of the half range
    source: str = "<profile>"       # the file it came from (error messages)

    def buttons(self) -> dict[str, int]:
        """Each bound button's key → its code."""
        return {k: getattr(self, k) for k in BUTTON_KEYS if getattr(self, k) is not None}


def button_name(code: int) -> str:
    """The first evdev name of a button code (the profile's spelling for help lines), or its number."""
    return next((n for n, c in BTN_CODES.items() if c == code), str(code))


def load_profile(path: str | Path | None = None) -> GamepadProfile:
    """The profile in the TOML file at `path` (None: the packaged Xbox-style profile)."""
    path = Path(path) if path is not None else DEFAULT_PROFILE
    try:
        text = path.read_text()
    except OSError as exc:
        raise ProfileError(f"{path}: cannot read: {exc.strerror or exc}") from None
    return parse_profile(text, str(path))


def parse_profile(text: str, source: str = "<profile>") -> GamepadProfile:
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{source}: not valid TOML: {exc}") from None
    return profile_from_table(table, source)


def profile_from_table(table: dict, source: str = "<profile>") -> GamepadProfile:
    def fail(key: str, why: str) -> ProfileError:
        return ProfileError(f"{source}: {key}: {why}")

    for key, value in table.items():
        if key not in _TOP_KEYS:
            raise fail(key, f"unknown key (known: {', '.join(sorted(_TOP_KEYS))})")
        if key in _AXIS_KEYS or key in _SCALE_KEYS:
            if not isinstance(value, dict):
                raise fail(key, f"expected a table such as {key}.{_AXIS_KEYS.get(key, _SCALE_KEYS.get(key))[0]} = …")
            allowed = _AXIS_KEYS.get(key) or _SCALE_KEYS[key]
            for sub in value:
                if sub not in allowed:
                    raise fail(f"{key}.{sub}", f"unknown axis (this robot moves in {', '.join(allowed)} here)")

    require = table.get("require_enable_button", True)
    if not isinstance(require, bool):
        raise fail("require_enable_button", f"expected true or false, got {require!r}")
    deadzone = _number(table.get("deadzone", 0.05), "deadzone", fail)
    if not 0.0 <= deadzone < 1.0:
        raise fail("deadzone", f"expected a fraction of the half range in [0, 1), got {deadzone}")

    buttons = {key: _code(table.get(key), key, BTN_CODES, KEY_MAX, "button", fail) for key in BUTTON_KEYS}
    seen: dict[int, str] = {}
    for key, code in buttons.items():
        if code is None:
            continue
        if code in seen:
            raise fail(key, f"{button_name(code)} is also {seen[code]}")
        seen[code] = key
    if require and buttons["enable_button"] is None:
        raise fail("enable_button", "required while require_enable_button is true (the deadman)")

    axes: list[AxisBinding] = []
    used: dict[int, str] = {}
    for group, kind in (("axis_linear", "linear"), ("axis_angular", "angular")):
        for dof_name, name in table.get(group, {}).items():
            key = f"{group}.{dof_name}"
            code = _code(name, key, ABS_CODES, ABS_MAX, "axis", fail)
            if code is None:
                continue
            if code in used:
                raise fail(key, f"axis {name} is also {used[code]}")
            used[code] = key
            scale_key = f"scale_{kind}.{dof_name}"
            if dof_name not in table.get(f"scale_{kind}", {}):
                raise fail(scale_key, f"missing: the scale of {key}")
            scale = _number(table[f"scale_{kind}"][dof_name], scale_key, fail)
            turbo_key = f"scale_{kind}_turbo.{dof_name}"
            turbo = _number(table.get(f"scale_{kind}_turbo", {}).get(dof_name, scale), turbo_key, fail)
            for k, s in ((scale_key, scale), (turbo_key, turbo)):
                if not -1.0 <= s <= 1.0:
                    raise fail(k, f"expected a deflection in [-1, 1] (the wire's range), got {s}")
            if scale * turbo < 0.0:
                raise fail(turbo_key, f"has the other sign than {scale_key} ({turbo} vs {scale})")
            axes.append(AxisBinding(DOFS.index(dof_name), key, code, scale, turbo))
    for kind, group in (("linear", "axis_linear"), ("angular", "axis_angular")):
        for scale_group in (f"scale_{kind}", f"scale_{kind}_turbo"):
            for dof_name in table.get(scale_group, {}):
                if dof_name not in table.get(group, {}):
                    raise fail(f"{scale_group}.{dof_name}", f"a scale without an axis ({group}.{dof_name})")
    if not axes:
        raise fail("axis_linear", "no axis bound: the pad would drive nothing")
    return GamepadProfile(axes=tuple(sorted(axes, key=lambda a: a.dof)), require_enable_button=require,
                          deadzone=deadzone, source=source, **buttons)


def _number(value, key: str, fail) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise fail(key, f"expected a finite number, got {value!r}")
    return float(value)


def _code(value, key: str, names: dict[str, int], largest: int, kind: str, fail) -> int | None:
    """An evdev name or code → the code; None for no binding (absent or -1)."""
    if value is None or (isinstance(value, int) and not isinstance(value, bool) and value == -1):
        return None
    if isinstance(value, str):
        if value in names:
            return names[value]
        prefix = "ABS_" if kind == "axis" else "BTN_"
        raise fail(key, f"{value!r} is not an evdev {kind} name (e.g. {prefix}…, or give the integer code)")
    if isinstance(value, int) and not isinstance(value, bool):
        low = 0 if kind == "axis" else 1
        if low <= value <= largest:
            return value
        raise fail(key, f"{kind} code {value} outside {low}…{largest}")
    raise fail(key, f"expected an evdev {kind} name or code, got {value!r}")
