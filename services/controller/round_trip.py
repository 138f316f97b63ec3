"""The CAN round trip, measured with polls the drives answer: a remote (RTR) request out, its reply back.

CANSimple frames carry no timestamp, so how long a frame spent on its way cannot be read from it;
a poll and its reply can be timed on one clock. The CAN master (can_master.py) sends an RTR for
`PROBE_COMMAND` to one axis at a time, at `rate`, and hands the reply's arrival back here. The
round trip covers both directions and the drive's turnaround: a host → drive command (the poll)
and a drive → host data frame (the reply), the two paths of the control loop's own frames,
through whatever gateway sits between them (services/faults/can_gateway.py sorts RTR polls with
the commands and Get_* replies with the feedback).

`PROBE_COMMAND` is Get_Bus_Voltage_Current (0x17): every drive answers its RTR (services/robot/axis.py;
ODrive 0.6 likewise), and nothing else here sends it, since the drives send only Heartbeat and
Get_Encoder_Estimates cyclically. A reply to a Get_Encoder_Estimates poll would share its id with
the 500 Hz cyclic frames and could not be told from them.

The estimate (`round_trip`) is the largest of the last `window` measured round trips: robust to
jitter (a bound, not an average) and to loss (a probe unanswered after `timeout` is discarded and
counted, never measured). At most one probe is outstanding, and a reply is matched to it by its
axis; a reply with no probe outstanding for its axis (one that came after its timeout, or an answer
to another host's poll) is counted as `unmatched` and ignored. The frames carry no sequence number:
a reply later than its timeout by a whole round of the axes (three probe intervals) would be taken
for the next probe of its axis, one short measurement that the window's maximum outweighs.

Pure: times in (s, the master's clock), nodes to poll and round trips out; no bus, no clock.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

from sharedctl.protocol.odrive_enums import CommandId

from ..lifecycle import Schedule

PROBE_COMMAND = CommandId.GET_BUS_VOLTAGE_CURRENT
DEFAULT_RATE = 10.0       # Hz, probes sent
DEFAULT_TIMEOUT = 0.2     # s: a probe unanswered this long is lost
DEFAULT_WINDOW = 20       # measured round trips the estimate is the largest of


@dataclass
class RoundTripProbe:
    nodes: tuple[int, ...]
    rate: float = DEFAULT_RATE            # Hz; 0: no probes
    timeout: float = DEFAULT_TIMEOUT      # s
    window: int = DEFAULT_WINDOW
    sent: int = 0                         # probes sent
    replies: int = 0                      # probes answered within `timeout` (each one a measured round trip)
    timeouts: int = 0                     # probes unanswered within `timeout`, discarded
    unmatched: int = 0                    # replies with no probe outstanding for their axis
    round_trips: deque = field(init=False)
    outstanding: tuple[int, float] | None = field(default=None, init=False)   # (node, sent at)
    schedule: Schedule | None = field(default=None, init=False)               # the probes' send times
    turn: int = field(default=0, init=False)                                  # index of the next node to poll
    round_trip: float = field(default=math.nan, init=False)   # s, the estimate; NaN until a round trip is measured

    def __post_init__(self) -> None:
        if not (self.rate >= 0.0 and self.timeout > 0.0 and self.window >= 1 and self.nodes):
            raise ValueError("a round-trip probe needs nodes, rate ≥ 0, timeout > 0 and window ≥ 1")
        self.round_trips = deque(maxlen=self.window)
        self.schedule = Schedule(self.rate, start=-math.inf) if self.rate > 0.0 else None

    def due(self, now: float) -> int | None:
        """The node to poll now, or None: probes are `1/rate` apart, one outstanding at most (a probe that
        waits for its reply delays the next, until it times out), round robin over the nodes."""
        if self.schedule is None:
            return None
        self.expire(now)
        if self.outstanding is not None or not self.schedule.due(now):
            return None
        node = self.nodes[self.turn % len(self.nodes)]
        self.turn += 1
        return node

    def probe_sent(self, node: int, at: float) -> None:
        """The poll to `node` left at `at` (s)."""
        self.outstanding = (node, at)
        self.sent += 1

    def reply(self, node: int, at: float) -> float | None:
        """The reply of `node` arrived at `at` (s): the round trip it measured (s), None if it matched no probe
        within its timeout."""
        if self.outstanding is None or self.outstanding[0] != node:
            self.unmatched += 1
            return None
        sent_at = self.outstanding[1]
        self.outstanding = None
        round_trip = at - sent_at
        if round_trip > self.timeout:
            self.timeouts += 1       # late: the probe counts as lost whether or not `due` had expired it yet
            return None
        round_trip = max(round_trip, 0.0)
        self.replies += 1
        self.round_trips.append(round_trip)
        self.round_trip = max(self.round_trips)
        return round_trip

    def expire(self, now: float) -> None:
        """Discard the outstanding probe if it has waited longer than `timeout`."""
        if self.outstanding is not None and now - self.outstanding[1] > self.timeout:
            self.outstanding = None
            self.timeouts += 1

    def counts(self) -> dict:
        """The counters, for the daemon's summary."""
        return {"sent": self.sent, "replies": self.replies, "timeouts": self.timeouts, "unmatched": self.unmatched}
