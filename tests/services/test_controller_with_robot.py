"""`sharedctl controller` against the real `sharedctl robot` process (host-local udp_multicast, loopback Zenoh).

The test joins the CAN bus as a listener (it records the controller's frames) and a Zenoh
session connected to both processes (RobotState from the controller, GroundTruth from the
robot — the truth is only for checking, the controller never sees it).
"""
from __future__ import annotations

import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol import keys
from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.messages import ControlRequest, Event, GroundTruth, OperatorCommand, RobotState
from sharedctl.protocol.msgpack_codec import decode_message, encode_message
from sharedctl.protocol.odrive_enums import AxisState
from sharedctl.services import can_bus, zenoh_session
from sharedctl.services.summary_output import read_json

from .processes import reap
from .processes import wait_for as _wait_for

pytestmark = pytest.mark.processes   # real processes / sockets: never in a parallel worker

NODES = (0, 1, 2)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("", 0))
        return s.getsockname()[1]


class BusListener(threading.Thread):
    """Records the host → drive frames and the drives' latest heartbeats (decoded with the codec)."""

    def __init__(self, port: int) -> None:
        super().__init__(daemon=True)
        self.bus = can_bus.open_bus(can_bus.resolve("udp_multicast", None, {"port": port}))
        self.log: list[tuple[float, object]] = []
        self.heartbeats: dict[int, cs.Heartbeat] = {}
        self._halt = threading.Event()

    def run(self) -> None:
        while not self._halt.is_set():
            msg = self.bus.recv(timeout=0.05)
            if msg is None:
                continue
            try:
                frame = cs.decode(msg.arbitration_id, bytes(msg.data), msg.is_remote_frame, dlc=msg.dlc, nodes=NODES)
            except ProtocolError:
                continue
            if isinstance(frame, cs.Heartbeat):
                self.heartbeats[frame.node_id] = frame
            elif isinstance(frame, (cs.SetInputTorque, cs.SetAxisState, cs.Estop, cs.ClearErrors)):
                self.log.append((time.monotonic(), frame))

    def armed(self) -> bool:
        return all(n in self.heartbeats and self.heartbeats[n].axis_state is AxisState.CLOSED_LOOP_CONTROL
                   for n in NODES)

    def frames(self, kind, node=None, since=0.0):
        return [(t, f) for t, f in list(self.log)
                if isinstance(f, kind) and t >= since and (node is None or f.node_id == node)]

    def stop(self) -> None:
        self._halt.set()
        self.join(timeout=2.0)
        self.bus.shutdown()


def wait_for(predicate, timeout: float, what: str) -> None:
    _wait_for(predicate, timeout, what, poll=0.02)


@pytest.fixture
def system(tmp_path):
    port, z_robot, z_ctrl = free_udp_port(), zenoh_session.free_loopback_port(), zenoh_session.free_loopback_port()
    can_args = ["--can-interface", "udp_multicast", "--can-option", f"port={port}", "--robot-id", "itest"]
    cli = [sys.executable, "-m", "sharedctl.services.cli"]
    listener = BusListener(port)
    listener.start()
    procs = [
        # the simulated robot is the plant: on a busy host give it the controller's default priority too
        subprocess.Popen(["nice", "-n", "-10", *cli, "robot", *can_args, "--zenoh-listen", f"tcp/127.0.0.1:{z_robot}"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True),
        subprocess.Popen(cli + ["controller", *can_args, "--zenoh-listen", f"tcp/127.0.0.1:{z_ctrl}", "--quiet",
                                "--feedback-timeout-ms", "150",    # the robot runs unprivileged on a busy host
                                "--json", str(tmp_path / "controller.json")],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True),
    ]
    procs[1].summary_path = tmp_path / "controller.json"
    session = zenoh_session.open_session(connect=[f"tcp/127.0.0.1:{z_robot}", f"tcp/127.0.0.1:{z_ctrl}"])
    try:
        yield procs[0], procs[1], session, listener
    finally:
        session.close()
        reap(procs)
        listener.stop()


def test_controller_drives_the_simulated_robot_estops_when_it_goes_silent_and_stops_cleanly(system):
    robot, controller, session, listener = system
    states: list[RobotState] = []
    truths: list[GroundTruth] = []
    events: list[Event] = []
    session.declare_subscriber(keys.state_key("itest"),
                               lambda s: states.append(decode_message(s.payload.to_bytes(), expect=RobotState)))
    session.declare_subscriber(keys.truth_key("itest"),
                               lambda s: truths.append(decode_message(s.payload.to_bytes(), expect=GroundTruth)))
    session.declare_subscriber(keys.events_key("itest"),
                               lambda s: events.append(decode_message(s.payload.to_bytes(), expect=Event)))
    pub = session.declare_publisher(keys.operator_cmd_key("itest"))

    wait_for(listener.armed, 20.0, "the robot's three axes in CLOSED_LOOP_CONTROL")
    wait_for(lambda: len(truths) > 5 and len(states) > 5, 10.0, "telemetry and ground truth")
    q_start = np.array(truths[-1].q)
    for seq in range(1, 76):                                          # 1.5 s of +y deflection at 50 Hz
        pub.put(encode_message(OperatorCommand(
            operator_id="itester", session_id="i1", seq=seq, send_time=time.time(), joystick=(0.0, 0.6, 0.0),
            q_d=tuple(q_start), qd_d=(0.0, 0.0, 0.0), qdd_d=(0.0, 0.0, 0.0), deadman=True, estop=False,
            control_request=ControlRequest.NONE)))
        time.sleep(0.02)
    q_truth = np.array(truths[-1].q)
    assert q_truth[1] - q_start[1] > 0.02, [(round(e.time % 1000, 3), e.text) for e in events]   # moved along +y
    assert not states[-1].estop_active
    # hands off (silent operator): u_s = 0 in the safe set, the robot rolls to rest on wheel friction
    wait_for(lambda: np.linalg.norm(truths[-1].qd) < 1e-3 and np.linalg.norm(states[-1].qd_hat) < 1e-3, 10.0, "rest")
    wait_for(lambda: states[-1].lease_holder is None, 2.0, "the silent operator's lease to expire (1 s)")
    time.sleep(0.1)
    s = states[-1]
    assert s.authority.value == "human" and s.lease_holder is None and s.link.staleness_ms > 1000
    np.testing.assert_allclose(s.q, truths[-1].q, atol=0.005)        # odometry vs ground truth, at rest
    assert s.link.can_feedback_age_ms < 50

    robot.send_signal(signal.SIGTERM)                                  # CAN feedback stops → estop
    assert robot.wait(timeout=5) == 0
    wait_for(lambda: states[-1].estop_active, 2.0, "estop after the robot went silent")
    assert any(e.kind.value == "estop" and "CAN feedback" in e.text for e in events)

    t_term = time.monotonic()
    controller.send_signal(signal.SIGTERM)
    out, err = controller.communicate(timeout=5)
    assert controller.returncode == 0, err
    assert time.monotonic() - t_term < 2.0

    def sent_since_term(n):
        return [f for _, f in listener.frames((cs.SetInputTorque, cs.SetAxisState), n, since=t_term)]

    # the controller has exited, but the listener thread may not have read its last frames off the socket yet
    wait_for(lambda: all(sent_since_term(n) and isinstance(sent_since_term(n)[-1], cs.SetAxisState) for n in NODES),
             2.0, "the listener to read the controller's last frames")
    for n in NODES:
        after = sent_since_term(n)
        assert any(isinstance(f, cs.SetInputTorque) and f.input_torque == 0.0 for f in after)
        assert isinstance(after[-1], cs.SetAxisState) and after[-1].requested_state is AxisState.IDLE
    assert read_json(controller.summary_path)["estops"] == 1          # the one when the robot went silent


def test_the_controllers_json_summary_counts_its_ticks_missed_deadlines_and_jitter(system):
    """Two seconds with the robot, then SIGTERM: every deadline of the run was either ticked or skipped
    (ticks + missed ≈ elapsed × 500 Hz), the lateness quantiles are ordered, and the drives' frames were read."""
    robot, controller, _, listener = system
    wait_for(listener.armed, 20.0, "the robot's three axes in CLOSED_LOOP_CONTROL")
    time.sleep(2.0)
    controller.send_signal(signal.SIGTERM)
    _, err = controller.communicate(timeout=5)
    assert controller.returncode == 0, err
    summary = read_json(controller.summary_path)
    deadlines = summary["elapsed_s"] * 500.0
    assert summary["elapsed_s"] > 2.0 and abs(summary["ticks"] + summary["missed"] - deadlines) < 0.05 * deadlines + 10
    assert summary["rate_hz"] == pytest.approx(summary["ticks"] / summary["elapsed_s"])
    assert 0.0 < summary["jitter_p50_us"] <= summary["jitter_p99_us"] <= summary["jitter_max_us"] + 10.0
    assert summary["late"] >= 0 and summary["frames_rx"] > summary["ticks"]
    assert 0.0 < summary["loop_cpu_p50_us"] < 2000.0 and 0.0 < summary["torque_out_p50_us"] < 2000.0
