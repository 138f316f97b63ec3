"""Zenoh QoS per stream (services/zenoh_qos.py): the control path first, telemetry after it, and what a
subscriber receives says so — the priority, congestion control and express flag travel with each sample."""
import ast
import threading
import time
from pathlib import Path

import pytest
import zenoh

from sharedctl.protocol import keys
from sharedctl.services import zenoh_qos
from sharedctl.services.zenoh_session import free_loopback_port, open_session

SERVICES = Path(__file__).resolve().parents[2] / "services"
CONTROL = ("operator_cmd", "lease")
TELEMETRY = ("state", "events", "alive", "truth")


def rank(priority: zenoh.Priority) -> int:
    """Zenoh's priorities are numbered from REAL_TIME (1, served first) to BACKGROUND (7)."""
    return int(priority)


def test_operator_commands_and_the_lease_go_before_every_telemetry_stream():
    assert int(zenoh.Priority.REAL_TIME) < int(zenoh.Priority.DATA)       # the numbering rank() relies on
    for control in CONTROL:
        for telemetry in TELEMETRY:
            assert rank(zenoh_qos.STREAMS[control].priority) < rank(zenoh_qos.STREAMS[telemetry].priority)


def test_the_control_path_is_never_dropped_and_never_batched():
    for control in CONTROL:
        qos = zenoh_qos.STREAMS[control]
        assert qos.congestion_control == zenoh.CongestionControl.BLOCK
        assert qos.express is True


def test_robot_state_is_dropped_rather_than_queued_behind_a_full_link():
    assert zenoh_qos.STREAMS["state"].congestion_control == zenoh.CongestionControl.DROP


def test_the_ground_truth_is_below_zenohs_default_priority():
    assert rank(zenoh_qos.STREAMS["truth"].priority) > rank(zenoh_qos.DEFAULT.priority)


def test_a_key_of_no_known_kind_keeps_zenohs_default():
    assert zenoh_qos.for_key("sharedctl/v1/robot1/unknown") == zenoh_qos.DEFAULT
    assert zenoh_qos.for_key("elsewhere/robot1/state") == zenoh_qos.DEFAULT
    assert zenoh_qos.for_key(keys.state_key("robot1")) == zenoh_qos.STREAMS["state"]


def _receiver_and_sender():
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    receiver = open_session(listen=[endpoint])
    sender = open_session(connect=[endpoint])
    return receiver, sender


@pytest.mark.processes
def test_each_stream_reaches_a_subscriber_with_its_qos():
    receiver, sender = _receiver_and_sender()
    try:
        samples, arrived = {}, threading.Event()
        streams = {keys.operator_cmd_key("r1"): "operator_cmd", keys.state_key("r1"): "state",
                   keys.events_key("r1"): "events", keys.alive_key("r1", "controller"): "alive",
                   keys.truth_key("r1"): "truth"}

        def on_sample(sample) -> None:
            samples[str(sample.key_expr)] = (sample.priority, sample.congestion_control, sample.express)
            if len(samples) == len(streams):
                arrived.set()
        subscriber = receiver.declare_subscriber(keys.robot_pattern("r1"), on_sample)
        publishers = {key: zenoh_qos.declare_publisher(sender, key) for key in streams}
        for _ in range(200):
            for publisher in publishers.values():
                publisher.put(b"x")
            if arrived.wait(0.05):
                break
        assert arrived.is_set(), f"only {sorted(samples)} arrived"
        for key, kind in streams.items():
            qos = zenoh_qos.STREAMS[kind]
            assert samples[key] == (qos.priority, qos.congestion_control, qos.express), kind
        for publisher in publishers.values():
            publisher.undeclare()
        subscriber.undeclare()
    finally:
        sender.close()
        receiver.close()


@pytest.mark.processes
def test_a_lease_reply_comes_back_with_the_qos_its_query_asked_for():
    """The reply to a query travels with the query's QoS (Zenoh ignores a reply's own priority)."""
    receiver, sender = _receiver_and_sender()
    try:
        key = keys.lease_key("r1")
        queryable = receiver.declare_queryable(key, lambda query: query.reply(key, b"granted"))
        replies, deadline = [], time.monotonic() + 10.0      # until the two peers have met
        while not replies and time.monotonic() < deadline:
            replies = [r.ok for r in sender.get(key, payload=b"take", timeout=1.0, **zenoh_qos.options("lease"))
                       if r.ok is not None]
            time.sleep(0.02)
        assert replies, "no reply"
        qos = zenoh_qos.STREAMS["lease"]
        assert (replies[0].priority, replies[0].congestion_control, replies[0].express) == (
            qos.priority, qos.congestion_control, qos.express)
        queryable.undeclare()
    finally:
        sender.close()
        receiver.close()


def _publisher_declarations(path: Path):
    """The `….declare_publisher(…)` calls of one module, as (receiver name or None, line)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        call = isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
        if call and node.func.attr == "declare_publisher":
            owner = node.func.value.id if isinstance(node.func.value, ast.Name) else None
            yield owner, node.lineno


def test_every_process_declares_its_publishers_with_their_streams_qos():
    """A process's publisher of a sharedctl key gets its QoS from zenoh_qos.py, never Zenoh's defaults by accident;
    the studies (the lab) are free to do otherwise."""
    offenders = []
    for path in sorted(SERVICES.rglob("*.py")):
        if "studies" in path.parts or path.name == "zenoh_qos.py":
            continue
        offenders += [f"{path.relative_to(SERVICES)}:{line}" for owner, line in _publisher_declarations(path)
                      if owner != "zenoh_qos"]
    assert offenders == []
