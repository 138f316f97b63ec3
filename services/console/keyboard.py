"""The keyboard virtual joystick: key presses in, a deflected handle out. Pure (times are arguments).

A terminal reports key presses, never key releases, and repeats a held key (after a delay of
a few hundred ms, then ~30 Hz). So a press pushes the handle one step along its axis, and a
spring brings the handle back to centre: after `hold` seconds without a press on that axis it
moves towards 0 at 1/`return_time` per second (full deflection is centred in `return_time`,
~0.3 s). A held key keeps re-deflecting the handle; a released one lets it spring back.

Keys: arrows or W/A/S/D deflect x (right/left) and y (up/down), Q/E yaw (counter-clockwise /
clockwise); space is the deadman (on while space keeps repeating; `toggle` latches it: unsafe); X or Esc
requests an emergency stop, C clears that request; T / R ask to take / release control (sent
for `request_time` seconds).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sharedctl.protocol.messages import ControlRequest

# key name -> (axis, direction); axis 0 = x, 1 = y, 2 = yaw
AXIS_KEYS: dict[str, tuple[int, float]] = {
    "right": (0, +1.0), "d": (0, +1.0), "left": (0, -1.0), "a": (0, -1.0),
    "up": (1, +1.0), "w": (1, +1.0), "down": (1, -1.0), "s": (1, -1.0),
    "q": (2, +1.0), "e": (2, -1.0),
}
_ESCAPES = {"\x1b[A": "up", "\x1b[B": "down", "\x1b[C": "right", "\x1b[D": "left",
            "\x1bOA": "up", "\x1bOB": "down", "\x1bOC": "right", "\x1bOD": "left"}


def parse_keys(text: str) -> list[str]:
    """Raw terminal input → key names: arrows ("up", …), "space", "esc", or the lower-case character.

    A lone ESC (not followed by "[" or "O") is "esc"; an unknown escape sequence is skipped.
    """
    keys: list[str] = []
    i = 0
    while i < len(text):
        ch = text[i]
        if ch == "\x1b":
            seq = text[i:i + 3]
            if seq in _ESCAPES:
                keys.append(_ESCAPES[seq])
                i += 3
                continue
            if len(text) > i + 1 and text[i + 1] in "[O":
                j = i + 2                      # skip an unknown CSI/SS3 sequence up to its final byte
                while j < len(text) and not ("@" <= text[j] <= "~"):
                    j += 1
                i = j + 1
                continue
            keys.append("esc")
        elif ch == " ":
            keys.append("space")
        elif ch.isprintable():
            keys.append(ch.lower())
        i += 1
    return keys


@dataclass
class VirtualJoystick:
    """A spring-centred 3-axis handle with a deadman, an estop request and a control request."""

    dof: int = 3
    step: float = 0.5            # deflection added per press (normalised units)
    hold: float = 0.06           # s a press holds the handle before the spring acts
    return_time: float = 0.3     # s for the spring to centre a full deflection
    deadman_mode: str = "hold"   # "hold" | "toggle" (latches: not a deadman, docs/console.md)
    deadman_hold: float = 0.7    # s the deadman stays on after a space press in "hold" mode (a terminal
                                 # reports no key release; 0.7 s spans the usual 0.66 s first-repeat delay)
    request_time: float = 0.5    # s a take/release request is repeated
    reach: np.ndarray = field(default_factory=lambda: np.array([0.5, 0.5, 0.5]))  # m, m, rad at full deflection

    def __post_init__(self) -> None:
        if self.deadman_mode not in ("toggle", "hold"):
            raise ValueError("deadman_mode must be 'toggle' or 'hold'")
        self.reach = np.broadcast_to(np.asarray(self.reach, float), (self.dof,)).copy()
        self._value = np.zeros(self.dof)
        self._last_press = np.full(self.dof, -np.inf)
        self._updated = None
        self._deadman_on = False
        self._deadman_until = -np.inf
        self.estop = False
        self._request = ControlRequest.NONE
        self._request_until = -np.inf

    # ----- input -----------------------------------------------------------
    def press(self, key: str, now: float) -> None:
        """Apply one key press at time `now` (s, any monotonic clock)."""
        self._advance(now)
        if key in AXIS_KEYS:
            axis, sign = AXIS_KEYS[key]
            if axis < self.dof:
                self._value[axis] = float(np.clip(self._value[axis] + sign * self.step, -1.0, 1.0))
                self._last_press[axis] = now
        elif key == "space":
            if self.deadman_mode == "toggle":
                self._deadman_on = not self._deadman_on
            else:
                self._deadman_until = now + self.deadman_hold
        elif key in ("x", "esc"):
            self.estop = True
        elif key == "c":
            self.estop = False
        elif key in ("t", "r"):
            self._request = ControlRequest.TAKE if key == "t" else ControlRequest.RELEASE
            self._request_until = now + self.request_time

    def press_all(self, keys: list[str], now: float) -> None:
        for key in keys:
            self.press(key, now)

    # ----- output ----------------------------------------------------------
    def deflection(self, now: float) -> np.ndarray:
        """The handle's normalised deflection in [−1, 1] per axis at `now`."""
        self._advance(now)
        return self._value.copy()

    def deadman(self, now: float) -> bool:
        return self._deadman_on if self.deadman_mode == "toggle" else now < self._deadman_until

    def control_request(self, now: float) -> ControlRequest:
        return self._request if now < self._request_until else ControlRequest.NONE

    def wish(self, pose: np.ndarray, now: float) -> np.ndarray:
        """The operator's wish q_d: the current pose offset by the deflection times `reach`."""
        return np.asarray(pose, float) + self.reach * self.deflection(now)

    # ----- the spring ------------------------------------------------------
    def _advance(self, now: float) -> None:
        if self._updated is not None and now > self._updated:
            rate = 1.0 / self.return_time
            for axis in range(self.dof):
                release = max(self._updated, self._last_press[axis] + self.hold)
                dt = now - release
                if dt > 0:
                    v = self._value[axis]
                    self._value[axis] = np.sign(v) * max(0.0, abs(v) - rate * dt)
        self._updated = now if self._updated is None else max(self._updated, now)
