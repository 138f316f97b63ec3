"""The real `sharedctl fault-gateway` between two host-local buses: feedback frames lost, delayed
and cut by a bus-off window as set, command frames (outside `can.ids`) untouched, the babbling
node heard on both buses, the gateway's counters agreeing with what arrived."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time

import can
import pytest

from sharedctl.services.can_bus import open_bus, resolve, vcan_available
from sharedctl.services.children import free_udp_port

from .processes import reap, wait_for

pytestmark = pytest.mark.processes

RATE = 500.0             # frames/s in each direction (throughput is measured by hand, see docs/services.md)
SECONDS = 2.0
TORQUE, ENCODER = 0x0E, 0x09     # node 0 Set_Input_Torque (command), Get_Encoder_Estimates (feedback)
FAULTS = ["can.ids=feedback", "can.loss=0.1", "can.delay_ms=5", "can.busoff=1.0,0.3", "can.babble=200,0x000"]


def gateway_argv(bus_args, tmp_path):
    argv = [sys.executable, "-m", "sharedctl.services.cli", "fault-gateway", *bus_args, "--fault-seed", "5",
            "--arm-on-signal", "--stats", str(tmp_path / "gw.json"), "--ready", str(tmp_path / "ready"),
            "--duration", "60"]
    for spec in FAULTS:
        argv += ["--fault", spec]
    return argv


def run_stream(controller_spec, robot_spec, bus_args, tmp_path):
    proc = subprocess.Popen(gateway_argv(bus_args, tmp_path), stdout=subprocess.DEVNULL)
    buses = []
    try:
        wait_for(lambda: (tmp_path / "ready").exists() or proc.poll() is not None, 20.0, "the gateway", poll=0.05)
        assert proc.poll() is None
        buses = [open_bus(controller_spec), open_bus(robot_spec)]
        got = {"controller": {}, "robot": {}, "babble": [0, 0]}
        running = True

        def reader(k, bus, want):
            while running:
                msg = bus.recv(0.05)
                if msg is None:
                    continue
                if msg.arbitration_id == 0x000:
                    got["babble"][k] += 1
                elif msg.arbitration_id == want:
                    got["controller" if k == 0 else "robot"].setdefault(bytes(msg.data[:4]), time.monotonic())
        threads = [threading.Thread(target=reader, args=(0, buses[0], ENCODER)),
                   threading.Thread(target=reader, args=(1, buses[1], TORQUE))]
        for t in threads:
            t.start()
        proc.send_signal(signal.SIGUSR1)
        start = time.monotonic()
        sent = {}
        n = int(RATE * SECONDS)
        for i in range(n):
            while time.monotonic() < start + i / RATE:
                time.sleep(0.0002)
            key = i.to_bytes(4, "little")
            sent[key] = (time.monotonic(), time.time())
            buses[0].send(can.Message(arbitration_id=TORQUE, data=key + bytes(4), is_extended_id=False))
            buses[1].send(can.Message(arbitration_id=ENCODER, data=key + bytes(4), is_extended_id=False))
        time.sleep(0.3)
        running = False
        for t in threads:
            t.join()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
    finally:
        reap([proc])
        for bus in buses:
            bus.shutdown()
    return sent, got, json.loads((tmp_path / "gw.json").read_text())


def check(sent, got, report):
    n = len(sent)
    commands, feedback = got["robot"], got["controller"]
    assert len(commands) == n                                   # not selected by can.ids: all forwarded
    assert report["command"]["passed_unimpaired"] == n
    # run time of each frame on the gateway's clock (its arming, wall time), 20 ms clear of the window's edges
    run_time = {k: wall - report["armed_wall"] for k, (_, wall) in sent.items()}
    outside = [k for k, t in run_time.items() if not 0.98 <= t < 1.32]
    inside = [k for k, t in run_time.items() if 1.02 <= t < 1.28]
    assert len(inside) > 100
    assert not any(k in feedback for k in inside)               # bus-off: nothing forwarded
    loss = 1 - sum(k in feedback for k in outside) / len(outside)
    assert abs(loss - 0.1) < 0.04, loss
    delays = sorted(feedback[k] - sent[k][0] for k in outside if k in feedback)
    assert delays[len(delays) // 2] >= 0.005                    # the set 5 ms (more on a loaded host)
    fb = report["feedback"]
    assert fb["delay_total_s"] / fb["delayed"] == pytest.approx(0.005, rel=0.01)   # + order-keeping holds
    assert fb["latency_ms_mean"] >= 5.0
    assert fb["forwarded"] == len(feedback) and fb["blackout_dropped"] + fb["lost"] == n - len(feedback)
    assert min(got["babble"]) > 0.5 * 200 * SECONDS               # the flood reached both buses
    return report


def test_gateway_on_udp_multicast_impairs_the_selected_frames(tmp_path):
    ports = free_udp_port(), free_udp_port()
    specs = [resolve("udp_multicast", None, udp_port=p) for p in ports]
    report = check(*run_stream(*specs, ["--controller-port", str(ports[0]), "--robot-port", str(ports[1])], tmp_path))
    assert report["cpu_us_per_frame"] > 0


@pytest.mark.skipif(not (vcan_available("vcan0") and vcan_available("vcan1")),
                    reason="needs SocketCAN vcan0 and vcan1 (deploy/vcan-setup.sh); this kernel has no vcan")
def test_gateway_on_socketcan_impairs_the_selected_frames(tmp_path):
    specs = [resolve("socketcan", "vcan0"), resolve("socketcan", "vcan1")]
    check(*run_stream(*specs, ["--interface", "socketcan", "--controller-channel", "vcan0",
                               "--robot-channel", "vcan1"], tmp_path))
