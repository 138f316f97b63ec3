"""The gamepad as the operator's handle: evdev events in; deflection, deadman, estop and control
request out. Pure: no device, no clock (times are arguments); gamepad_device.py feeds it.

It answers what the keyboard's `VirtualJoystick` answers (`deflection`, `deadman`, `estop`,
`control_request`, `wish`), so the console turns either into OperatorCommand the same way.

* Frames: events are collected and applied at each SYN_REPORT, as evdev delivers a device's
  state change (linux Documentation/input/event-codes.rst).
* Axes: normalised from the device's absinfo: centre (min + max)/2, half range (max − min)/2;
  within the flat zone — the larger of the device's `flat` and the profile's `deadzone` × half
  range — the axis reads 0, beyond it (|raw − centre| − flat)/(half − flat), clipped to [−1, 1]
  (continuous at the edge of the zone, full at the end of travel).
* Deadman (teleop_twist_joy's rule): with `require_enable_button` the pad drives only while
  the enable or the turbo button is held (turbo: the turbo scales); otherwise deflection 0 and
  deadman False. Releasing it is a "stop" action at once, so the console sends the hands-off
  command now rather than at its next tick. After a (re)connect a button already held does not
  enable until it has been let go (a pad plugged in with LB taped down never drives).
* Buttons: estop latches until clear (both actions); take / release set the control request
  for `request_time` s and are actions (the console asks its lease client).
* SYN_DROPPED (the client's buffer overran): events up to and including the next SYN_REPORT
  are ignored and `needs_resync` is set; hands-off until `resync` with the device's state as
  its ioctls report it (EVIOCGABS, EVIOCGKEY).
* Unplug (`disconnect`): hands-off and a "stop" action; `status` says "gamepad disconnected"
  until `connect` again.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from sharedctl.protocol.messages import ControlRequest

from .gamepad_profile import DOFS, GamepadProfile, button_name

EV_SYN, EV_KEY, EV_ABS = 0x00, 0x01, 0x03
SYN_REPORT, SYN_DROPPED = 0, 3
JOYSTICK_BUTTONS = range(0x120, 0x140)   # BTN_JOYSTICK … BTN_THUMBR: what makes a device a joystick or a pad

ACTIONS = ("stop", "estop", "clear_estop", "take", "release")


class GamepadError(Exception):
    """No usable gamepad: none found, it cannot be opened, or it lacks an axis or button the profile binds."""


@dataclass(frozen=True)
class AbsInfo:
    """An absolute axis as EVIOCGABS reports it (evdev's AbsInfo)."""

    value: int
    min: int
    max: int
    fuzz: int = 0
    flat: int = 0
    resolution: int = 0


@dataclass(frozen=True)
class DeviceInfo:
    """What an opened event device is: its identity and its capabilities."""

    path: str
    name: str
    phys: str
    absinfo: Mapping[int, AbsInfo]       # EV_ABS code → its range (value: at open)
    keys: frozenset[int]                 # EV_KEY codes it has

    def is_joystick(self) -> bool:
        """ABS_X and ABS_Y and a joystick or gamepad button (not a touchpad, not a motion sensor)."""
        return 0 in self.absinfo and 1 in self.absinfo and any(k in JOYSTICK_BUTTONS for k in self.keys)


@dataclass(frozen=True)
class Snapshot:
    """The device's current state as its ioctls report it: axis values and the buttons held."""

    axes: Mapping[int, int]
    pressed: frozenset[int] = frozenset()


@dataclass(frozen=True)
class AxisScale:
    centre: float
    half: float
    flat: float

    @classmethod
    def of(cls, info: AbsInfo, deadzone: float) -> "AxisScale":
        half = (info.max - info.min) / 2.0
        return cls(centre=(info.max + info.min) / 2.0, half=half, flat=min(max(float(info.flat), deadzone * half),
                                                                             0.99 * half))

    def normalise(self, raw: int) -> float:
        off = raw - self.centre
        if abs(off) <= self.flat:
            return 0.0
        n = (abs(off) - self.flat) / (self.half - self.flat)
        return float(np.copysign(min(n, 1.0), off))


@dataclass
class GamepadCounters:
    events: int = 0
    frames: int = 0
    ignored: int = 0        # events of codes the profile does not bind
    dropped: int = 0        # SYN_DROPPED: the client's buffer overran
    resyncs: int = 0
    connects: int = 0
    disconnects: int = 0


class Gamepad:
    """One pad under one profile; `connect` it to a device, `feed` it the device's events."""

    def __init__(self, profile: GamepadProfile, reach=(0.5, 0.5, 0.5), request_time: float = 0.5) -> None:
        self.profile = profile
        self.reach = np.broadcast_to(np.asarray(reach, float), (len(DOFS),)).copy()
        self.request_time = request_time
        self.counters = GamepadCounters()
        self.device: DeviceInfo | None = None
        self.estop = False
        self._buttons = {code: key for key, code in profile.buttons().items()}
        self._axis_codes = {a.code for a in profile.axes}
        self._scales: dict[int, AxisScale] = {}
        self._raw: dict[int, int] = {}
        self._pressed: frozenset[int] = frozenset()
        self._pending: dict[tuple[int, int], int] = {}
        self._dropping = False          # after SYN_DROPPED, until the next SYN_REPORT
        self.needs_resync = False       # the device's state must be read (`resync`)
        self._armed = False
        self._engaged = False
        self._request = ControlRequest.NONE
        self._request_until = -np.inf
        self._actions: list[str] = []

    # ----- the device ------------------------------------------------------
    def check(self, device: DeviceInfo) -> None:
        """Raise GamepadError, naming the profile's key, if `device` lacks an axis or button the profile binds."""
        where = f"{self.profile.source}"
        for axis in self.profile.axes:
            info = device.absinfo.get(axis.code)
            if info is None:
                raise GamepadError(f"{where}: {axis.key}: {device.name!r} ({device.path}) has no axis code "
                                   f"{axis.code}; its axes: {sorted(device.absinfo)}")
            if info.max <= info.min:
                raise GamepadError(f"{where}: {axis.key}: {device.name!r} reports the axis's range as "
                                   f"{info.min}…{info.max}")
        for code, key in self._buttons.items():
            if code not in device.keys:
                raise GamepadError(f"{where}: {key}: {device.name!r} ({device.path}) has no button "
                                   f"{button_name(code)}")

    def connect(self, device: DeviceInfo, state: Snapshot, now: float) -> None:
        """Start reading `device` (checked first), whose current state is `state`."""
        self.check(device)
        self.device = device
        self._scales = {a.code: AxisScale.of(device.absinfo[a.code], self.profile.deadzone) for a in self.profile.axes}
        self._pending.clear()
        self._dropping = self.needs_resync = False
        self._pressed = frozenset()
        self._raw = {}
        self._armed = False
        self.counters.connects += 1
        self._set_state(state, now)        # arms only if neither enable nor turbo is held

    def disconnect(self, now: float) -> None:
        """The device is gone (unplugged, read error): hands-off at once."""
        if self.device is None:
            return
        self.device = None
        self._pending.clear()
        self._dropping = self.needs_resync = False
        self._pressed = frozenset()
        self.counters.disconnects += 1
        self._engaged = False
        self._actions.append("stop")          # hands-off now, whether it was driving or not

    def resync(self, state: Snapshot, now: float) -> None:
        """After SYN_DROPPED: the device's state as its ioctls report it now."""
        self.needs_resync = False
        self.counters.resyncs += 1
        self._set_state(state, now)

    @property
    def status(self) -> str | None:
        """Why the pad cannot drive now (hands-off), or None."""
        if self.device is None:
            return "gamepad disconnected"
        if self._dropping or self.needs_resync:
            return "gamepad events dropped: resynchronising"
        return None

    # ----- events ----------------------------------------------------------
    def feed(self, event, now: float) -> None:
        """One event (anything with evdev's `type`, `code`, `value`)."""
        if self.device is None:
            return
        self.counters.events += 1
        etype, code, value = event.type, event.code, event.value
        if etype == EV_SYN:
            if code == SYN_DROPPED:
                self.counters.dropped += 1
                self._pending.clear()
                self._dropping = True
                self._update(now)
            elif code == SYN_REPORT:
                if self._dropping:
                    self._dropping, self.needs_resync = False, True
                else:
                    self._apply(now)
            return
        if self._dropping:
            return
        if (etype == EV_ABS and code in self._axis_codes) or (etype == EV_KEY and code in self._buttons):
            self._pending[(etype, code)] = int(value)
        else:
            self.counters.ignored += 1

    def take_actions(self) -> list[str]:
        """What happened since the last call, in order: "stop" (the pad stopped driving: send now), "estop",
        "clear_estop", "take", "release"."""
        actions, self._actions = self._actions, []
        return actions

    # ----- outputs (VirtualJoystick's interface) ---------------------------
    def deflection(self, now: float) -> np.ndarray:
        """Normalised deflection in [−1, 1] per degree of freedom (x, y, yaw); 0 unless the pad drives."""
        d = np.zeros(len(DOFS))
        if not self._engaged:
            return d
        turbo = self._held(self.profile.enable_turbo_button)
        for axis in self.profile.axes:
            raw = self._raw.get(axis.code)
            n = 0.0 if raw is None else self._scales[axis.code].normalise(raw)
            d[axis.dof] = np.clip(n * (axis.scale_turbo if turbo else axis.scale), -1.0, 1.0)
        return d

    def deadman(self, now: float) -> bool:
        return self._engaged

    def control_request(self, now: float) -> ControlRequest:
        return self._request if now < self._request_until else ControlRequest.NONE

    def wish(self, pose, now: float) -> np.ndarray:
        """The operator's wish q_d: the current pose offset by the deflection times `reach`."""
        return np.asarray(pose, float) + self.reach * self.deflection(now)

    def clear_estop(self) -> None:
        self.estop = False

    # ----- state -----------------------------------------------------------
    def _held(self, code: int | None) -> bool:
        return code is not None and code in self._pressed

    def _enable_held(self) -> bool:
        return self._held(self.profile.enable_button) or self._held(self.profile.enable_turbo_button)

    def _apply(self, now: float) -> None:
        self.counters.frames += 1
        if not self._pending:
            return
        raw: dict[int, int] = {}
        pressed = set(self._pressed)
        for (etype, code), value in self._pending.items():
            if etype == EV_ABS:
                raw[code] = value
            elif value:
                pressed.add(code)           # 1 press, 2 autorepeat
            else:
                pressed.discard(code)
        self._pending.clear()
        self._set_state(Snapshot(raw, frozenset(pressed)), now)

    def _set_state(self, state: Snapshot, now: float) -> None:
        pressed = frozenset(c for c in state.pressed if c in self._buttons)
        for code in sorted(pressed - self._pressed):
            self._press(self._buttons[code], now)
        self._pressed = pressed
        self._raw.update((code, int(v)) for code, v in state.axes.items() if code in self._axis_codes)
        if not self._enable_held():
            self._armed = True
        self._update(now)

    def _press(self, key: str, now: float) -> None:
        if key == "estop_button":
            self.estop = True
            self._actions.append("estop")
        elif key == "clear_estop_button":
            self.estop = False
            self._actions.append("clear_estop")
        elif key in ("take_control_button", "release_control_button"):
            take = key == "take_control_button"
            self._request = ControlRequest.TAKE if take else ControlRequest.RELEASE
            self._request_until = now + self.request_time
            self._actions.append("take" if take else "release")

    def _update(self, now: float) -> None:
        """Recompute whether the pad drives; a drop from driving is a "stop" action."""
        in_sync = self.device is not None and not self._dropping and not self.needs_resync
        if not in_sync:
            engaged = False
        elif not self.profile.require_enable_button:
            engaged = True
        else:
            engaged = self._armed and self._enable_held()
        if self._engaged and not engaged:
            self._actions.append("stop")
        self._engaged = engaged
