"""Recorded gamepad event streams (tests/fixtures/gamepad/, format in its README.md), played two ways: straight
into the pure `Gamepad` (`replay`), and as evdev devices behind a backend the reader opens (`RecordedDevice`,
`RecordedBackend`). Names are resolved with python-evdev's own `ecodes`, not the profile's table."""
from __future__ import annotations

import errno
import json
from dataclasses import astuple, dataclass, field, replace
from pathlib import Path

import numpy as np
from evdev import InputEvent, ecodes
from evdev.device import AbsInfo as EvdevAbsInfo

from sharedctl.services.console.gamepad import EV_SYN, SYN_REPORT, AbsInfo, DeviceInfo, Gamepad, Snapshot
from sharedctl.services.console.operator import CommandCounter, JoystickCommandSource

FIXTURES = Path(__file__).parents[1] / "fixtures" / "gamepad"
ROOT_DEPLOY = Path(__file__).parents[2] / "deploy" / "gamepad"
POSE = (1.0, 2.0, 0.1)


def _code(name) -> int:
    return name if isinstance(name, int) else ecodes.ecodes[name]


@dataclass
class Recording:
    device: DeviceInfo
    pressed: frozenset[int]
    lines: list = field(default_factory=list)   # InputEvent | ("state", Snapshot) | ("error", errno)

    @classmethod
    def load(cls, name: str) -> "Recording":
        rows = [json.loads(line) for line in (FIXTURES / name).read_text().splitlines()
                if line.strip() and not line.lstrip().startswith("#")]
        head = rows[0]["device"]
        device = DeviceInfo(path=head["path"], name=head["name"], phys=head["phys"],
                            absinfo={_code(k): AbsInfo(*v) for k, v in head["absinfo"].items()},
                            keys=frozenset(_code(k) for k in head["keys"]))
        lines = []
        for row in rows[1:]:
            if isinstance(row, list):
                sec, usec, etype, code, value = row
                lines.append(InputEvent(sec, usec, _code(etype), _code(code), value))
            elif "state" in row:
                state = row["state"]
                lines.append(("state", Snapshot({_code(k): v for k, v in state["abs"].items()},
                                                frozenset(_code(k) for k in state["pressed"]))))
            else:
                lines.append(("error", getattr(errno, row["error"])))
        return cls(device, frozenset(_code(k) for k in head.get("pressed", [])), lines)

    def initial_state(self) -> Snapshot:
        return Snapshot({code: info.value for code, info in self.device.absinfo.items()}, self.pressed)


@dataclass
class Frame:
    """After one SYN_REPORT (or SYN_DROPPED, or an error): its events, the command the console would send at that
    moment, and the pad's actions."""

    time: float
    events: list
    command: object
    actions: list

    @property
    def deflection(self) -> np.ndarray:
        return np.asarray(self.command.joystick)


def replay(name: str, profile) -> tuple[Gamepad, list[Frame]]:
    """Play a recording into a new Gamepad; a command (at POSE) after every frame; frames[0]: at connect."""
    rec = Recording.load(name)
    pad = Gamepad(profile)
    source = JoystickCommandSource(pad, CommandCounter("op", "s1"))
    now = rec.lines[0].timestamp()
    pad.connect(rec.device, rec.initial_state(), now)
    frames = [Frame(now, [], source.command(now, POSE, send_time=0.0), pad.take_actions())]
    state, events = rec.initial_state(), []
    for line in rec.lines:
        if isinstance(line, tuple):
            kind, value = line
            if kind == "state":
                state = value
                continue
            pad.disconnect(now)
            frames.append(Frame(now, [("error", value)], source.command(now, POSE, send_time=0.0),
                                pad.take_actions()))
            break
        now = line.timestamp()
        events.append(line)
        pad.feed(line, now)
        if pad.needs_resync:
            pad.resync(state, now)
        if line.type == EV_SYN:
            frames.append(Frame(now, events, source.command(now, POSE, send_time=0.0), pad.take_actions()))
            events = []
    return pad, frames


def after(frames: list[Frame], code: str, value: int | None = None, nth: int = 1) -> Frame:
    """The frame holding the `nth` event named `code` (SYN_*, ABS_*, BTN_*; with `value`, only of that value)."""
    want = ({"SYN": ecodes.EV_SYN, "ABS": ecodes.EV_ABS}.get(code[:3], ecodes.EV_KEY), _code(code))
    count = 0
    for frame in frames:
        for event in frame.events:
            if isinstance(event, tuple) or (event.type, event.code) != want:
                continue
            if value is None or event.value == value:
                count += 1
                if count == nth:
                    return frame
    raise AssertionError(f"no {code} = {value} (#{nth}) in the recording")


class RecordedDevice:
    """An evdev InputDevice that plays a recording: each read() returns the next frame (up to and including a
    SYN_REPORT), then raises BlockingIOError; an error line raises that OSError from then on. The ioctls
    (absinfo, active_keys) report the state the delivered events and the state lines leave."""

    def __init__(self, rec: Recording, path: str | None = None) -> None:
        self.rec = rec
        self.path = path or rec.device.path
        self.name, self.phys = rec.device.name, rec.device.phys
        self._abs = {code: info.value for code, info in rec.device.absinfo.items()}
        self._pressed = set(rec.pressed)
        self._at = 0
        self.closed = False
        self.unplugged = False
        self.frames_read = 0

    def capabilities(self, absinfo: bool = True):
        info = self.rec.device.absinfo
        return {ecodes.EV_SYN: [0, 1, 3], ecodes.EV_KEY: sorted(self.rec.device.keys),
                ecodes.EV_ABS: [(code, self.absinfo(code)) for code in info]}

    def absinfo(self, code: int) -> EvdevAbsInfo:
        return EvdevAbsInfo(*astuple(replace(self.rec.device.absinfo[code], value=self._abs[code])))

    def active_keys(self) -> list[int]:
        return sorted(self._pressed)

    def read(self):
        if self.closed:
            raise OSError(errno.EBADF, "closed")
        events = []
        while self._at < len(self.rec.lines):
            line = self.rec.lines[self._at]
            if isinstance(line, tuple):
                kind, value = line
                if kind == "error":
                    if events:
                        break
                    self.unplugged = True                   # its device node is gone with it
                    raise OSError(value, "No such device")
                self._abs.update(value.axes)
                self._pressed = set(value.pressed)
                self._at += 1
                continue
            self._at += 1
            events.append(line)
            if line.type == ecodes.EV_ABS:
                self._abs[line.code] = line.value
            elif line.type == ecodes.EV_KEY:
                (self._pressed.add if line.value else self._pressed.discard)(line.code)
            if line.type == EV_SYN and line.code == SYN_REPORT:
                break
        if not events:
            raise BlockingIOError(errno.EAGAIN, "Resource temporarily unavailable")
        self.frames_read += 1
        return iter(events)

    @property
    def done(self) -> bool:
        return self._at >= len(self.rec.lines)

    def close(self) -> None:
        self.closed = True


class RecordedBackend:
    """The host's event devices: path → device (a device opens as itself; one whose recording has reached its error
    is unplugged: its path no longer exists)."""

    def __init__(self, *devices: RecordedDevice, unreadable: tuple[str, ...] = ()) -> None:
        self.devices = {d.path: d for d in devices}
        self.unreadable = set(unreadable)
        self.opened: list[str] = []

    def list_devices(self) -> list[str]:
        return sorted((p for p in self.devices if p not in self.unreadable and not self.devices[p].unplugged),
                      key=lambda p: int(p.rsplit("event", 1)[1]))

    def open(self, path: str):
        if path in self.unreadable:
            raise PermissionError(errno.EACCES, "Permission denied", path)
        if path not in self.devices or self.devices[path].unplugged:
            raise FileNotFoundError(errno.ENOENT, "No such file or directory", path)
        self.opened.append(path)
        device = self.devices[path]
        device.closed = False
        return device

    def exists(self, path: str) -> bool:
        return path in self.devices and not self.devices[path].unplugged
