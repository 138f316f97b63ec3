"""Replay and ordering guard for operator messages: per-session sequence numbers and send-time age. Pure.

A message (an `OperatorCommand`, or a `LeaseRequest` with its own guard) is taken only if, for
its session:

1. **Order** — its `seq` is newer than the newest taken seq of that session; an equal seq is
   `duplicate_seq` (a replay or a duplicated delivery), a smaller one `out_of_order_seq`.
2. **Age** — its send time fits the receiver's clock. The sender's clock is another host's:
   `offset = receive − send_time` is the one-way delay *plus* the clock offset between the
   hosts, and the offset is unknown. So the age is measured relative to the session's own best
   delivery: `age = offset − min(offset of the session's taken messages over the last
   `window` s)`. The clock offset cancels (a drift of a few ppm is absorbed by the window);
   what remains is how much later this message arrives than the fastest one did. The receive
   time here is the receiver's **monotonic** clock (the constant between it and the wall clock
   cancels like the hosts' offset), so a step of the receiver's wall clock changes no age; the
   senders (the console) stamp their messages with a wall clock that never steps
   (`lifecycle.steady_wall`), so a step of theirs changes none either. A message
   with `age > max_age` (0.5 s by default) is `stale`: held back by a relay, re-sent from a
   capture, or overtaken by events. A constant delay is not staleness — the operator timeout
   and the link health report it.
3. **Clock skew** (optional, for sites whose hosts are synchronised by chrony/PTP) — with
   `max_skew` set, `|offset| > max_skew` is `clock_skew`. This bounds the absolute age too, and
   refuses a capture replayed into a restarted controller that has forgotten the session.

The first message of a session has no reference, nor has one after `window` seconds without a
taken message (so a lasting change of the delay is accepted again after at most `window`
seconds): only the skew bound applies to those. Without a
receive wall time (`wall_now=None`) only the order is checked. At most `max_sessions` sessions
are remembered besides the pinned ones (the least recently active are forgotten first), so memory
is bounded whatever a sender does; the controller pins every session the lease let act (`pin`), so a
flood of other sessions cannot push the holder's out and have a captured message of it taken as new.
"""
from __future__ import annotations

import math
from collections import OrderedDict, deque
from dataclasses import dataclass, field

DEFAULT_MAX_AGE = 0.5        # s a message may arrive later than the session's best delivery
DEFAULT_WINDOW = 10.0        # s over which the best delivery (smallest offset) is taken
DEFAULT_MAX_SESSIONS = 64


@dataclass
class _Session:
    newest_seq: int
    offsets: deque = field(default_factory=deque)   # (receive time, offset), offsets increasing: a sliding minimum


@dataclass
class ReplayGuard:
    """Per-session order and age check; `admit` returns None (taken) or the rejection reason."""

    max_age: float = DEFAULT_MAX_AGE
    max_skew: float | None = None
    window: float = DEFAULT_WINDOW
    max_sessions: int = DEFAULT_MAX_SESSIONS
    _sessions: OrderedDict = field(default_factory=OrderedDict)
    _pinned: OrderedDict = field(default_factory=OrderedDict)      # sessions the lease let act (`pin`)

    def __post_init__(self) -> None:
        if not self.max_age > 0 or not self.window > 0 or self.max_sessions < 1:
            raise ValueError("max_age and window must be positive, max_sessions at least 1")
        if self.max_skew is not None and not self.max_skew > 0:
            raise ValueError("max_skew must be positive (or None: no absolute bound)")

    def admit(self, session_id: str, seq: int, send_time: float, now: float,
              wall_now: float | None = None) -> str | None:
        """Judge one message received at `now` (s, monotonic) and `wall_now` (s, wall clock, or None)."""
        track = self._sessions.get(session_id)
        if track is not None and seq <= track.newest_seq:
            return "duplicate_seq" if seq == track.newest_seq else "out_of_order_seq"
        offset = None
        if wall_now is not None and math.isfinite(wall_now) and math.isfinite(send_time):
            if self.max_skew is not None and abs(wall_now - send_time) > self.max_skew:
                return "clock_skew"
            offset = now - send_time            # on the monotonic clock: a wall-clock step changes no age
            if track is not None and self._age(track, offset, now) > self.max_age:
                return "stale"
        if track is None:
            track = self._sessions[session_id] = _Session(seq)
            self._forget_beyond_limit()
        self._sessions.move_to_end(session_id)
        track.newest_seq = seq
        if offset is not None:
            while track.offsets and track.offsets[-1][1] >= offset:
                track.offsets.pop()
            track.offsets.append((now, offset))
        return None

    def pin(self, session_id: str) -> None:
        """Keep a remembered session through floods: the controller pins a session once the lease let it
        act. Forgetting takes the least recently active unpinned session; pinned ones go (oldest pin
        first) only when they alone exceed `max_sessions`. Without pins, sessions that never held the
        lease could push the holder's out, and a captured command of it would then pass as new."""
        track = self._sessions.get(session_id)
        if track is not None and session_id not in self._pinned:
            self._pinned[session_id] = None
            while len(self._pinned) > self.max_sessions:
                self._pinned.popitem(last=False)

    def _forget_beyond_limit(self) -> None:
        """Down to `max_sessions` unpinned sessions, the least recently active first (the pinned are
        a subset of the remembered, at most `max_sessions` of them)."""
        excess = len(self._sessions) - len(self._pinned) - self.max_sessions
        if excess > 0:
            for key in [k for k in self._sessions if k not in self._pinned][:excess]:
                del self._sessions[key]

    def age(self, session_id: str, send_time: float, now: float, wall_now: float | None = None) -> float:
        """The relative age (s) a message of this session sent at `send_time` would have now (0 without a reference)."""
        track = self._sessions.get(session_id)
        return 0.0 if track is None else self._age(track, now - send_time, now)

    def _age(self, track: _Session, offset: float, now: float) -> float:
        while track.offsets and track.offsets[0][0] < now - self.window:
            track.offsets.popleft()
        return 0.0 if not track.offsets else offset - track.offsets[0][1]

    @property
    def sessions(self) -> int:
        return len(self._sessions)
