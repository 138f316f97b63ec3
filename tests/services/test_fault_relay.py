"""The real `sharedctl fault-relay` between two Zenoh sessions: loss, delay and duplication
measured on the far side, the relay's own counters agreeing, and the lease query forwarded."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from sharedctl.protocol import keys
from sharedctl.services.zenoh_session import free_loopback_port, open_session

from .processes import reap, wait_for

pytestmark = pytest.mark.processes

ROBOT = "robot1"
N = 400
PERIOD = 0.004


def test_relay_injects_operator_loss_and_delay_and_telemetry_duplicates(tmp_path):
    f_ep, c_ep = f"tcp/127.0.0.1:{free_loopback_port()}", f"tcp/127.0.0.1:{free_loopback_port()}"
    stats = tmp_path / "relay.json"
    controller = open_session(listen=[c_ep])
    relay = subprocess.Popen([sys.executable, "-m", "sharedctl.services.cli", "fault-relay", "--listen", f_ep,
                              "--connect", c_ep, "--robot-id", ROBOT, "--fault", "operator.loss=0.3",
                              "--fault", "operator.delay_ms=100", "--fault", "telemetry.duplicate=0.5",
                              "--fault-seed", "3", "--arm-on-signal", "--stats", str(stats), "--duration", "60"],
                             stdout=subprocess.DEVNULL)
    console = None
    try:
        console = open_session(connect=[f_ep])
        lock = threading.Lock()
        at_controller, at_console = {}, []

        def on_command(sample):
            data = sample.payload.to_bytes()
            with lock:
                at_controller.setdefault(data, time.monotonic())

        def on_state(sample):
            with lock:
                at_console.append(sample.payload.to_bytes())

        entities = [controller.declare_subscriber(keys.operator_cmd_key(ROBOT), on_command),
                    console.declare_subscriber(keys.state_key(ROBOT), on_state),
                    controller.declare_queryable(keys.PREFIX + f"/{ROBOT}/control/lease",
                                                 lambda q: q.reply(q.key_expr, b"granted"))]
        cmd_pub = console.declare_publisher(keys.operator_cmd_key(ROBOT))
        state_pub = controller.declare_publisher(keys.state_key(ROBOT))

        def both_ways():   # unarmed: probes pass unimpaired until the relay links both sides
            cmd_pub.put(b"probe")
            state_pub.put(b"probe")
            with lock:
                return b"probe" in at_controller and b"probe" in at_console
        wait_for(both_ways, 20.0, "the relay to link both sides", poll=0.1)

        replies = [r.ok.payload.to_bytes() for r in console.get(keys.PREFIX + f"/{ROBOT}/control/lease", timeout=5.0)
                   if r.ok is not None]
        assert replies == [b"granted"]

        relay.send_signal(signal.SIGUSR1)
        time.sleep(0.3)
        with lock:
            at_controller.clear()
            at_console.clear()
        sent = {}
        start = time.monotonic()
        for i in range(N):
            while time.monotonic() < start + i * PERIOD:
                time.sleep(0.0005)
            payload = b"cmd%d" % i
            sent[payload] = time.monotonic()
            cmd_pub.put(payload)
            state_pub.put(b"state%d" % i)
        time.sleep(0.8)
        relay.send_signal(signal.SIGTERM)
        assert relay.wait(10) == 0
        for e in entities:
            e.undeclare()
    finally:
        reap([relay])
        if console is not None:
            console.close()
        controller.close()

    report = json.loads(stats.read_text())
    with lock:
        delivered = {k: v for k, v in at_controller.items() if k in sent}
        states = list(at_console)
    loss = 1 - len(delivered) / N
    assert abs(loss - 0.3) < 0.08, loss
    latencies = sorted(delivered[k] - sent[k] for k in delivered)
    median = latencies[len(latencies) // 2]
    assert 0.1 <= median < 0.5, median              # the set 100 ms, plus the scheduling of a loaded host
    assert report["operator"]["latency_ms_mean"] >= 100
    assert report["operator"]["received"] == N and report["operator"]["lost"] == N - len(delivered)
    dup_rate = len(states) / N - 1
    assert abs(dup_rate - 0.5) < 0.1, dup_rate
    assert report["telemetry"]["duplicated"] == len(states) - N
    assert report["queries"]["replies"] == 1
    assert os.path.exists(stats)
