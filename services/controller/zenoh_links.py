"""The controller's Zenoh side: what it publishes (RobotState, events, Heartbeat messages and a
liveliness token), the operator commands it takes (command_intake.py) and the lease queries it
answers (lease_queries.py → lease.py).

Lease queries, like operator commands, wait in a Zenoh FIFO channel that the loop polls: no Python
callback thread takes the daemon's lock, so no flood of queries or commands can hold the loop. Each
poll judges at most `command_intake.BUDGET` commands, then answers at most `LEASE_BUDGET` queries:
a take or release never overtakes a command that was judged before it, and the loop's work per
poll is bounded whatever arrives (what is left waits for the next poll, 0.5 ms later; a full
channel holds the sender back inside Zenoh).
"""
from __future__ import annotations

import sys
import time

import zenoh

from sharedctl.protocol import keys
from sharedctl.protocol.msgpack_codec import encode_message

from .. import zenoh_qos
from . import command_intake, lease_queries
from .command_intake import CommandIntake, attachment_bytes

LEASE_CAPACITY = 64   # lease queries Zenoh holds for the loop
LEASE_BUDGET = 4      # lease queries answered per poll


class ControllerLinks:
    """The publishers, token, subscriber and queryable of robot `robot_id`'s controller (`role`) on `session`;
    `policy` judges the operator commands and holds the lease, `lock` is the daemon's; `lease_verify` checks the
    signature of each lease query (None: no operator identity)."""

    def __init__(self, session, robot_id: str, role: str, policy, lease_guard, lock, events, verbose: bool,
                 lease_verify=None) -> None:
        self.robot_id, self.policy, self.lease_guard, self.lock = robot_id, policy, lease_guard, lock
        self.lease_verify = lease_verify      # operator identity of lease queries (signing.py), or None
        self.events, self.verbose = events, verbose       # events: telemetry.EventLimiter
        self.state_pub = zenoh_qos.declare_publisher(session, keys.state_key(robot_id))
        self.event_pub = zenoh_qos.declare_publisher(session, keys.events_key(robot_id))
        self.alive_pub = zenoh_qos.declare_publisher(session, keys.alive_key(robot_id, role))
        self.token = session.liveliness().declare_token(keys.alive_key(robot_id, role))
        self.subscriber = session.declare_subscriber(keys.operator_cmd_key(robot_id), command_intake.channel())
        self.intake = CommandIntake(self.subscriber, policy)
        self.extra_intakes: list = []     # other operator inputs polled with the commands (ros2_links.py: Twists)
        self.queryable = session.declare_queryable(keys.lease_key(robot_id),
                                                   zenoh.handlers.FifoChannel(LEASE_CAPACITY))

    def apply_commands(self) -> None:
        """The operator commands that arrived, judged in arrival order, then the lease queries waiting
        (caller holds `lock`): at most `command_intake.BUDGET` and `LEASE_BUDGET` of them.

        Called by the loop between CAN frames and before each tick. Then the same for each of `extra_intakes`
        (each judges at most `command_intake.BUDGET` per poll as well)."""
        self.intake.apply()
        for intake in self.extra_intakes:
            intake.apply()
        for _ in range(LEASE_BUDGET):
            query = self.queryable.try_recv()
            if query is None:
                return
            self.answer_lease_query(query)

    def answer_lease_query(self, query) -> None:
        """Take/release control (lease_queries.py); every query gets a reply (caller holds `lock`)."""
        try:
            payload = query.payload.to_bytes() if query.payload is not None else b""
        except Exception:  # noqa: BLE001 — an unreadable payload is answered as an empty (refused) request
            payload = b""
        reply = lease_queries.answer(payload, self.policy.lease, self.lease_guard, self.policy.rejections,
                                     time.monotonic(), time.time(), self.policy.lease_limit,
                                     attachment_bytes(query), self.lease_verify)
        try:
            query.reply(keys.lease_key(self.robot_id), encode_message(reply))   # with its query's QoS (zenoh_qos)
        except Exception as exc:  # noqa: BLE001 — a vanished querier must not stop anything
            print(f"sharedctl controller: lease reply not sent: {exc}", file=sys.stderr)

    def emit(self, now: float, topic: str, kind: str, severity: str, text: str) -> None:
        """An event, at most one per topic per interval (`EventLimiter`); warnings and worse also to stderr."""
        event = self.events.make(now, time.time(), topic, kind, severity, text)
        if event is None:
            return
        if self.verbose and severity in ("warning", "error", "critical"):
            print(f"sharedctl controller: {severity}: {event.text}", file=sys.stderr, flush=True)
        try:
            self.event_pub.put(encode_message(event))
        except Exception as exc:  # noqa: BLE001 — telemetry must not stop the loop
            print(f"sharedctl controller: event not sent: {exc}", file=sys.stderr)

    def undeclare(self) -> None:
        for entity in (self.subscriber, self.queryable, self.token, self.state_pub, self.event_pub, self.alive_pub):
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 — closing anyway
                pass
