"""Zenoh QoS per stream: what each kind of message asks of the transport.

Zenoh gives every message a priority (one of seven transmission queues per link, the higher served
first), a congestion control (what a full transmission queue does: BLOCK the sender until there is
room, or DROP the message) and an express flag (sent at once, never batched with others). The
defaults (DATA, DROP, not express) treat every stream alike; here each of sharedctl's streams asks
for what it is, by the kind of its key (`sharedctl.protocol.keys.KINDS`):

    stream           priority          congestion  express  why
    operator_cmd     REAL_TIME         BLOCK       yes      the control path: the operator's wish and the Estop
                                                            flag; never dropped (a dropped Estop is a missed
                                                            stop), never waits behind a batch
    lease            REAL_TIME         BLOCK       yes      take / release control (queries; a reply has its query's):
                                                            the hand-over of authority
    state            INTERACTIVE_HIGH  DROP        yes      RobotState at 50 Hz: the operator's view; a newer one
                                                            replaces it, so one that meets a full queue is worth
                                                            nothing by the time there is room
    events           DATA_HIGH         BLOCK       no       rare (rate-limited) and each one matters once
    alive            DATA              DROP        no       Heartbeat messages at 1 Hz (liveliness tokens carry
                                                            presence; these carry the sequence)
    truth            DATA_LOW          DROP        no       the simulator's ground truth at 100 Hz: evaluation
                                                            only, never in the way of the control path

The ROS 2 topics of `controller --ros2` (rmw_zenoh's keys) publish as rmw_zenoh does for a keep-last
publisher: Zenoh's defaults (`ROS2_KEEP_LAST`), below every control stream.

`declare_publisher(session, key)` is how every process declares a publisher for a sharedctl key;
`options("lease")` goes with `Session.get` (a reply travels with its query's QoS). The fault relay
re-publishes a key with the same table, so a stream keeps its QoS through it; `sharedctl replay`
publishes every key with one QoS (`DEFAULT`), since streams of different priorities overtake one
another and a replay keeps the recorded order. `DEFAULT` is Zenoh's own (the bench compares the two: the
operator → torque latency with each, docs/performance.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import zenoh

from sharedctl.protocol import keys
from sharedctl.protocol.errors import KeyExprError


@dataclass(frozen=True, slots=True)
class StreamQos:
    """What one stream asks of the transport: its priority, congestion control and express flag."""

    priority: zenoh.Priority
    congestion_control: zenoh.CongestionControl
    express: bool

    def options(self) -> dict:
        """The keyword arguments of `declare_publisher`, `put`, `get` and `reply` that say it."""
        return {"priority": self.priority, "congestion_control": self.congestion_control, "express": self.express}


DEFAULT = StreamQos(zenoh.Priority.DATA, zenoh.CongestionControl.DROP, False)   # Zenoh's own defaults
#: the ROS 2 topics (`controller --ros2`: odom, authority): what rmw_zenoh gives a keep-last publisher — Zenoh's
#: defaults, below every sharedctl control stream
ROS2_KEEP_LAST = DEFAULT

STREAMS: dict[str, StreamQos] = {
    "operator_cmd": StreamQos(zenoh.Priority.REAL_TIME, zenoh.CongestionControl.BLOCK, True),
    "lease": StreamQos(zenoh.Priority.REAL_TIME, zenoh.CongestionControl.BLOCK, True),
    "state": StreamQos(zenoh.Priority.INTERACTIVE_HIGH, zenoh.CongestionControl.DROP, True),
    "events": StreamQos(zenoh.Priority.DATA_HIGH, zenoh.CongestionControl.BLOCK, False),
    "alive": StreamQos(zenoh.Priority.DATA, zenoh.CongestionControl.DROP, False),
    "truth": StreamQos(zenoh.Priority.DATA_LOW, zenoh.CongestionControl.DROP, False),
}
assert set(STREAMS) == set(keys.KINDS), "every kind of key has its QoS"


def for_key(key: str) -> StreamQos:
    """The QoS of the stream a concrete sharedctl key belongs to; Zenoh's `DEFAULT` for any other key (a relay
    or a replay passes on what it does not know as it is)."""
    try:
        return STREAMS[keys.parse_key(key).kind]
    except KeyExprError:
        return DEFAULT


def declare_publisher(session, key: str, qos: StreamQos | None = None):
    """A publisher on `key` with its stream's QoS (`qos` overrides it: the bench's comparison)."""
    return session.declare_publisher(key, **(qos or for_key(key)).options())


def options(kind: str) -> dict:
    """The keyword arguments of `Session.get` for a query of stream `kind` (the lease)."""
    return STREAMS[kind].options()
