"""Another master on the drives' bus (services/controller/can_master.py, "foreign"): frames this controller did
not send that command a drive make it Estop, with an Event naming them.

In-process: the daemon's reaction, tick by tick. With processes: a separate process sending Set_Input_Torque
frames encoded from the CANSimple DBC (tests/services/can_intruder.py) onto a running demo's bus."""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from sharedctl.protocol import cansimple as cs
from sharedctl.services.controller.daemon import Mode
from sharedctl.services.summary_output import read_json

from .processes import reap
from .test_controller_loop import arm, events, feed, make_daemon, message
from .test_controller_with_robot import BusListener, free_udp_port, wait_for

INTRUDER = Path(__file__).with_name("can_intruder.py")


def test_a_foreign_torque_frame_estops_at_the_next_tick_and_is_named():
    d = make_daemon()
    arm(d)
    d.master.bus.take()
    d.master.handle(message(cs.SetInputTorque(2, 4.0)), 10.0025)        # nobody here sent it
    feed(d, 10.003, heartbeat=False)
    d.tick(10.003)
    assert d.mode is Mode.ESTOPPED
    assert d.master.bus.take() == [cs.Estop(n) for n in (0, 1, 2)]
    texts = [e.text for e in events(d)]
    assert any("foreign CAN master" in t and "0x04E" in t and "node 2" in t for t in texts)
    assert any(t.startswith("ESTOP: foreign CAN master") for t in texts)


def test_while_another_master_keeps_sending_the_estop_is_sent_again_at_once_and_no_take_rearms_silently():
    d = make_daemon()
    arm(d)
    d.master.handle(message(cs.SetInputVel(0, 5.0, 0.0)), 10.0025)
    d.tick(10.003)
    d.master.bus.take()
    for k in range(1, 6):                                              # 100 Hz of foreign frames
        now = 10.003 + 0.01 * k
        d.master.handle(message(cs.SetInputTorque(0, 1.0 + k)), now)
        feed(d, now, heartbeat=False)
        d.tick(now)
    assert [f for f in d.master.bus.take() if isinstance(f, cs.Estop)] == [cs.Estop(n) for n in (0, 1, 2)] * 5
    assert d.master.foreign_commands == 6 and d.mode is Mode.ESTOPPED


@pytest.mark.processes
def test_a_process_sending_torque_frames_onto_a_running_demos_bus_is_stopped_within_50_ms(tmp_path):
    port = free_udp_port()
    listener = BusListener(port)
    listener.start()
    out = tmp_path / "demo.json"
    demo = subprocess.Popen([sys.executable, "-m", "sharedctl.services.cli", "demo", "--headless", "--duration", "8",
                             "--no-reference", "--can-interface", "udp_multicast", "--can-option", f"port={port}",
                             "--json", str(out), "--log-dir", str(tmp_path / "logs")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(listener.armed, 30.0, "the demo's drives armed")
        time.sleep(2.0)                                                # the scripted operator driving
        intruder = subprocess.run([sys.executable, str(INTRUDER), str(port), "0", "3.0", "200", "0.5"],
                                  capture_output=True, text=True, timeout=20)
        assert intruder.returncode == 0, intruder.stderr
        _, err = demo.communicate(timeout=60)
        assert demo.returncode in (0, 1), err            # 1: the demo reports the run's Estop as a failed run
    finally:
        reap([demo])
        listener.stop()
    foreign = [t for t, f in listener.frames(cs.SetInputTorque, 0) if f.input_torque == 3.0]
    assert foreign, "the intruder's frames were not on the bus"
    estops = [t for t, _ in listener.frames(cs.Estop, since=foreign[0])]
    assert estops and estops[0] - foreign[0] < 0.05, (estops[:1], foreign[0])
    summary = read_json(out)
    assert summary["failure"] is None                                  # every process ran to the end
    texts = [e["text"] for e in summary["event_log"]]
    assert any("foreign CAN master" in t and "0x00E" in t for t in texts), texts
    assert summary["estops"] >= 1
    assert summary["violations"] == 0 and summary["min_margin"] > 0.0
    assert summary["final_speed"] < 0.01                               # braked to a stop inside the set
