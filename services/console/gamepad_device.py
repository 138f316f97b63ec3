"""The gamepad's evdev shell: find and open the device, read its events without blocking, feed
them to the pure `Gamepad` (gamepad.py), and open the device again after an unplug.

* Which device: `--device PATH`, or the first event device (by number) that is a joystick —
  ABS_X, ABS_Y and a joystick or gamepad button, so not a touchpad or a motion sensor — and has
  every axis and button the profile binds. None: a `GamepadError` saying why (nothing readable:
  the user is not in group `input`; no joystick; a joystick without a bound button, naming the key).
* Reading: the device is non-blocking; `pump` reads what is there (BlockingIOError: nothing).
  SYN_DROPPED is answered with the device's state read by ioctl (EVIOCGABS per bound axis,
  EVIOCGKEY), as event-codes.rst asks.
* Unplug: any OSError from a read or an ioctl (ENODEV, EIO, …), or the device file gone, is a
  disconnect — the pad goes hands-off at once and the console keeps running. Every
  `reopen_period` s it looks for the device again: an event device of the same name at the same
  path or with the same `phys` (the port it is plugged into), which it connects as new (a button
  held meanwhile must be let go before it enables).

`EvdevBackend` is python-evdev (the `gamepad` extra), imported only when the console runs with
`--input gamepad`; tests give the reader a backend of recorded devices instead.
"""
from __future__ import annotations

import os
import re
import select
import time

from .gamepad import EV_ABS, EV_KEY, AbsInfo, DeviceInfo, Gamepad, GamepadError, Snapshot

REOPEN_PERIOD = 0.5   # s between looks for an unplugged pad (and checks that its device file still exists)


class EvdevBackend:
    """The event devices of this host, through python-evdev."""

    def __init__(self) -> None:
        import evdev    # the `gamepad` extra; a missing module names it (services/cli.py EXTRAS)

        self._evdev = evdev

    def list_devices(self) -> list[str]:
        """Readable /dev/input/event* paths, by event number."""
        return sorted(self._evdev.list_devices(), key=_event_number)

    def open(self, path: str):
        return self._evdev.InputDevice(path)

    def exists(self, path: str) -> bool:
        return os.path.exists(path)


def _event_number(path: str) -> tuple[int, str]:
    match = re.search(r"(\d+)$", path)
    return (int(match.group(1)) if match else 1 << 30, path)


def device_info(device) -> DeviceInfo:
    """An opened evdev InputDevice (or a recorded one) as a DeviceInfo."""
    caps = device.capabilities(absinfo=True)
    absinfo = {code: AbsInfo(*info) for code, info in caps.get(EV_ABS, [])}
    return DeviceInfo(path=str(device.path), name=device.name, phys=device.phys or "", absinfo=absinfo,
                      keys=frozenset(caps.get(EV_KEY, [])))


def read_state(device, axes) -> Snapshot:
    """The device's current axis values (`axes`: codes) and buttons held, by ioctl."""
    return Snapshot({code: device.absinfo(code).value for code in axes}, frozenset(device.active_keys()))


class GamepadReader:
    def __init__(self, pad: Gamepad, backend, path: str | None = None, reopen_period: float = REOPEN_PERIOD) -> None:
        self.pad = pad
        self.backend = backend
        self.path = path
        self.reopen_period = reopen_period
        self.device = None                  # the open evdev device, None while disconnected
        self.identity: DeviceInfo | None = None
        self.last_error: str | None = None
        self.read_errors = 0
        self._next_look = 0.0
        self._axes = [a.code for a in pad.profile.axes]

    # ----- opening ---------------------------------------------------------
    def open(self, now: float) -> DeviceInfo:
        """Open the pad at start; GamepadError if there is none that fits the profile."""
        if self.path is not None:
            device = self._open(self.path)
            try:
                info = device_info(device)
                self.pad.check(info)
                return self._connect(device, info, now)
            except OSError as exc:
                _close(device)
                raise GamepadError(f"{self.path}: cannot read: {exc.strerror or exc}") from None
            except GamepadError:
                _close(device)
                raise
        paths = self.backend.list_devices()
        if not paths:
            raise GamepadError("no gamepad found: no readable /dev/input/event* device (reading one needs "
                               "membership of group 'input'; see docs/console.md)")
        unfit: GamepadError | None = None
        for path in paths:
            try:
                device = self.backend.open(path)
            except OSError:
                continue
            try:
                info = device_info(device)
                if info.is_joystick():
                    self.pad.check(info)
                    return self._connect(device, info, now)
            except GamepadError as exc:
                unfit = unfit or exc
            except OSError:
                pass
            _close(device)
        if unfit is not None:
            raise unfit
        raise GamepadError(f"no gamepad found: none of the {len(paths)} readable input devices has joystick axes "
                           "and buttons (give --device /dev/input/eventN)")

    def _open(self, path: str):
        try:
            return self.backend.open(path)
        except FileNotFoundError:
            raise GamepadError(f"{path}: no such device") from None
        except PermissionError:
            raise GamepadError(f"{path}: permission denied: the user must be in group 'input' "
                               "(or a udev rule must grant access; see docs/console.md)") from None
        except OSError as exc:
            raise GamepadError(f"{path}: cannot open: {exc.strerror or exc}") from None

    def _connect(self, device, info: DeviceInfo, now: float) -> DeviceInfo:
        self.pad.connect(info, read_state(device, self._axes), now)
        self.device, self.identity = device, info
        self._next_look = now + self.reopen_period
        return info

    # ----- reading ---------------------------------------------------------
    def pump(self, now: float) -> list[str]:
        """Read what the device has (never blocks), or look for it again if it is gone; the pad's actions."""
        if self.device is None:
            if now >= self._next_look:
                self._next_look = now + self.reopen_period
                self._look_again(now)
            return self.pad.take_actions()
        try:
            for event in self.device.read():
                self.pad.feed(event, now)
                if self.pad.needs_resync:
                    self.pad.resync(read_state(self.device, self._axes), now)
        except BlockingIOError:
            pass
        except OSError as exc:
            self._lost(now, exc)
        if self.device is not None and now >= self._next_look:
            self._next_look = now + self.reopen_period
            if not self.backend.exists(self.identity.path):
                self._lost(now, FileNotFoundError(f"{self.identity.path} vanished"))
        return self.pad.take_actions()

    def wait(self, timeout: float, stop) -> None:
        """Until the device has events, at most `timeout` s (disconnected: until the next look)."""
        if self.device is None:
            stop.wait(timeout)
            return
        try:
            select.select([self.device], [], [], timeout)
        except (OSError, ValueError):
            pass    # the next pump's read reports it

    def run(self, stop, lock, on_actions) -> None:
        """The reader thread: wait for events, pump them under `lock`, hand the actions to `on_actions`."""
        while not stop.stopped:
            self.wait(0.1, stop)
            with lock:
                actions = self.pump(time.monotonic())
            if actions:
                on_actions(actions)

    def describe(self) -> str:
        """One line for the console's summary."""
        c = self.pad.counters
        name = "none" if self.identity is None else f"{self.identity.name!r} ({self.identity.path})"
        return (f"gamepad {name}: {c.frames} frames, {c.dropped} dropped (resynchronised {c.resyncs}), "
                f"{c.disconnects} disconnects, {c.connects} connects")

    def close(self) -> None:
        if self.device is not None:
            _close(self.device)
            self.device = None

    # ----- unplug ----------------------------------------------------------
    def _lost(self, now: float, exc: OSError) -> None:
        self.read_errors += 1
        self.last_error = exc.strerror or str(exc)
        _close(self.device)
        self.device = None
        self.pad.disconnect(now)
        self._next_look = now + self.reopen_period

    def _look_again(self, now: float) -> None:
        """The same pad back: same name, and the same path or the same phys."""
        want = self.identity
        for path in dict.fromkeys([want.path, *self.backend.list_devices()]):
            if not self.backend.exists(path):
                continue
            try:
                device = self.backend.open(path)
            except OSError:
                continue
            try:
                info = device_info(device)
                if info.name == want.name and (path == want.path or (info.phys and info.phys == want.phys)):
                    self._connect(device, info, now)
                    return
            except (GamepadError, OSError):
                pass
            _close(device)


def _close(device) -> None:
    try:
        device.close()
    except OSError:
        pass
