"""The relay's measured latency is the delay it added: a message that arrived after the run's t = 0
but before the faults were armed passes at once and must not enter the mean (the demo arms the relay
one telemetry period or more after the lease instant it gives as t = 0, and a message queued unarmed
may be published after the arming)."""
from __future__ import annotations

import heapq
import time

from sharedctl.services.faults.spec import parse, pipeline
from sharedctl.services.faults.zenoh_relay import ZenohRelay

from .zenoh_fakes import Sample


class _Publisher:
    def __init__(self) -> None:
        self.sent: list[bytes] = []
        self.attachments: list[bytes | None] = []

    def put(self, data: bytes, attachment: bytes | None = None) -> None:
        self.sent.append(data)
        self.attachments.append(attachment)


def _drain(relay: ZenohRelay) -> None:
    """Release every queued message at its release time (the scheduler thread's work, in line)."""
    while relay.heap:
        release, _, direction, key, data, arrival, seq, impaired, attachment = heapq.heappop(relay.heap)
        time.sleep(max(0.0, release - time.monotonic()))
        relay._publish(direction, key, data, arrival, seq, impaired, attachment)


def test_messages_before_arming_do_not_dilute_the_measured_delay():
    delay = 0.05
    plan = parse([f"operator.delay_ms={delay * 1000:g}"], 0)
    relay = ZenohRelay("tcp/127.0.0.1:1", "tcp/127.0.0.1:2", "robot1", pipeline(plan, "operator"),
                       pipeline(plan, "telemetry"))
    key = "sharedctl/robot1/operator/cmd"
    publisher = relay.publishers[key] = _Publisher()
    relay.sessions = {"controller": None, "console": None}     # publishers exist: no session is asked
    origin = time.monotonic()                       # the run's t = 0 (lease instant) ...
    for i in range(5):                              # ... then messages the unarmed relay passes at once,
        relay._on_sample("operator", Sample(b"early%d" % i, key))
    relay.arm(origin)                               # still queued when it is armed late, t = 0 in the past
    for i in range(5):
        relay._on_sample("operator", Sample(b"late%d" % i, key))
    _drain(relay)

    report = relay.report()["operator"]
    assert len(publisher.sent) == 10 and report["delivered"] == 10 and report["passed_before_arming"] == 5
    assert report["latency_ms_mean"] >= delay * 1000
    assert report["latency_ms_max"] < delay * 1000 + 500      # loose: only that it is the delay, not a stall


def test_an_attachment_travels_with_its_payload_and_a_replayed_payload_keeps_its_own():
    """An operator's signature is an attachment: a duplicated or replayed command must carry the signature of the
    command it copies, or a controller that verifies would refuse a copy the link made."""
    plan = parse(["operator.duplicate=1", "operator.replay=1,20"], 3)
    relay = ZenohRelay("tcp/127.0.0.1:1", "tcp/127.0.0.1:2", "robot1", pipeline(plan, "operator"),
                       pipeline(plan, "telemetry"))
    key = "sharedctl/robot1/operator/cmd"
    publisher = relay.publishers[key] = _Publisher()
    relay.sessions = {"controller": None, "console": None}
    relay.arm()
    for i in range(8):
        relay._on_sample("operator", Sample(b"cmd%d" % i, key, attachment=b"sig%d" % i))
        time.sleep(0.01)
    _drain(relay)
    pairs = list(zip(publisher.sent, publisher.attachments))
    assert len(pairs) > 8 and relay.report()["operator"]["replayed"] > 0
    assert all(attachment == b"sig" + data[3:] for data, attachment in pairs), pairs
