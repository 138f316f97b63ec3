"""What the controller admits beyond the wire's own bounds: a rate per operator session, and an operator's
wish within reach of the robot.

The wire protocol bounds what a message can say (protocol/README.md §2.4; the joystick in [−1, 1],
every number finite). Within those bounds a peer can still say harmful things: a desired pose of
1e308 m is a finite float, and a session may send ten thousand commands a second. Both are the
controller's policy, not the wire's (a wire bound is frozen within a major; these are settings):

* **`RateLimit`** — a token bucket per key (operator/session): `rate` messages per second
  sustained, `burst` at once. A message beyond it is refused (`rate_limited`) and costs nothing
  further. The keys are bounded (`max_keys`, least recently used forgotten): a flood of fresh
  sessions gets fresh buckets, but every one of them is a non-holder refused by the lease, and
  the intake judges a bounded number per poll (command_intake.py).
* **`WishBounds`** — the operator's wish q_d within `max_distance` of the robot's pose (norm over
  every coordinate, m and rad), its rates q̇_d within `max_rate` and q̈_d within `max_accel`
  (each component). Beyond: `out_of_bounds`. The defaults are an order of magnitude above
  anything a console or script sends (the joystick reaches 0.5 m; the paper's scripts stay
  inside a few metres), and far below where the control law's arithmetic would overflow.

An estop is honoured before either check (operator_input.py): a flood of estops stops the robot.

Pure: keys, times and numbers in, a reason or None out.
"""
from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, field

COMMAND_RATE = 250.0      # Hz per session: five times the console's 50 Hz, 2.5 times the bench's operator
COMMAND_BURST = 50        # commands at once (a second of a console's commands released by a link)
LEASE_RATE = 10.0         # Hz per session: a console asks every 0.25 s while it wants control
LEASE_BURST = 10


@dataclass
class RateLimit:
    rate: float = COMMAND_RATE
    burst: float = COMMAND_BURST
    max_keys: int = 256
    refused: int = 0
    _buckets: OrderedDict = field(default_factory=OrderedDict)   # key → (tokens, at)

    def admit(self, key: str, now: float) -> bool:
        """Take a token of `key`'s bucket at `now` (s, monotonic); False (and counted) if it is empty."""
        tokens, at = self._buckets.pop(key, (self.burst, now))
        tokens = min(self.burst, tokens + max(now - at, 0.0) * self.rate)
        allowed = tokens >= 1.0
        self._buckets[key] = (tokens - 1.0 if allowed else tokens, now)
        if len(self._buckets) > self.max_keys:
            self._buckets.popitem(last=False)
        if not allowed:
            self.refused += 1
        return allowed


@dataclass(frozen=True)
class WishBounds:
    max_distance: float = 10.0    # |q_d − q| (m, rad)
    max_rate: float = 20.0        # |q̇_d| per component (m/s, rad/s)
    max_accel: float = 200.0      # |q̈_d| per component (m/s², rad/s²)

    def judge(self, q_d, qd_d, qdd_d, pose) -> str | None:
        """None if the wish is admissible near `pose`, else "out_of_bounds"."""
        if math.dist(q_d, pose) > self.max_distance:
            return "out_of_bounds"
        if any(abs(x) > self.max_rate for x in qd_d) or any(abs(x) > self.max_accel for x in qdd_d):
            return "out_of_bounds"
        return None
