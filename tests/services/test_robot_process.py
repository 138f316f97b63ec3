"""`sharedctl robot` as a process, seen from outside.

The CAN client here is written only with python-can, cantools and the published DBC
(protocol/odrive_cansimple.dbc) — it does not import sharedctl.protocol — so these tests check
that a third-party CANSimple master can drive the simulated robot. The bus is python-can
udp_multicast on 239.74.163.2 with hop_limit=0 (host-local) and a free port per test.
"""
from __future__ import annotations

import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import cantools
import pytest

from sharedctl.services.summary_output import read_json
from sharedctl.services.zenoh_session import free_loopback_port

pytestmark = pytest.mark.processes   # real processes / sockets: never in a parallel worker

DBC_PATH = Path(__file__).resolve().parents[2] / "protocol" / "odrive_cansimple.dbc"
GROUP = "239.74.163.2"
NODES = (0, 1, 2)
CLOSED_LOOP_CONTROL, IDLE = 8, 1
TORQUE_CONTROL, PASSTHROUGH = 1, 1
WATCHDOG_TIMER_EXPIRED = 0x1000000


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class RobotProcess:
    """A `sharedctl robot` subprocess; its stdout lines are collected by a reader thread; with `summary_path`,
    its exit summary is written there as JSON (`--json`)."""

    def __init__(self, *extra: str, can_port: int, zenoh_port: int, summary_path: Path | None = None) -> None:
        self.zenoh_endpoint = f"tcp/127.0.0.1:{zenoh_port}"
        self.summary_path = summary_path
        cmd = [sys.executable, "-m", "sharedctl.services.cli", "robot",
               "--can-interface", "udp_multicast", "--can-channel", GROUP, "--can-option", f"port={can_port}",
               "--zenoh-listen", self.zenoh_endpoint, *extra, *(["--json", str(summary_path)] if summary_path else [])]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines: queue.Queue[str] = queue.Queue()
        self.output: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.output.append(line)
            self.lines.put(line)

    def wait_ready(self, timeout: float = 20.0) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.1)
            except queue.Empty:
                if self.proc.poll() is not None:
                    break
                continue
            if "sharedctl robot:" in line and "physics" in line:
                return line
        raise AssertionError(f"robot did not start: {''.join(self.output)}")

    def summary(self) -> dict | None:
        """The exit summary the process wrote (None: none)."""
        return read_json(self.summary_path)

    def stop(self, timeout: float = 5.0) -> int:
        """SIGTERM, wait; kill only as a last resort. Only the PID this test started."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        return self.proc.returncode


@pytest.fixture
def ports():
    return {"can_port": free_udp_port(), "zenoh_port": free_loopback_port()}


@pytest.fixture
def robot(ports, tmp_path):
    process = RobotProcess(**ports, summary_path=tmp_path / "robot.json")
    try:
        process.wait_ready()
        yield process
    finally:
        process.stop()


class CanSimpleClient:
    """A CANSimple master from the DBC alone (python-can + cantools)."""

    def __init__(self, can_port: int) -> None:
        self.db = cantools.database.load_file(str(DBC_PATH))
        self.bus = can.Bus(interface="udp_multicast", channel=GROUP, port=can_port, hop_limit=0, fd=False)

    def close(self) -> None:
        self.bus.shutdown()

    def send(self, node: int, name: str, **signals) -> None:
        message = self.db.get_message_by_name(f"Axis{node}_{name}")
        self.bus.send(can.Message(arbitration_id=message.frame_id, data=message.encode(signals), is_extended_id=False))

    def poll(self, node: int, name: str) -> None:
        message = self.db.get_message_by_name(f"Axis{node}_{name}")
        self.bus.send(can.Message(arbitration_id=message.frame_id, is_remote_frame=True, dlc=message.length,
                                  is_extended_id=False))

    def receive(self, timeout: float):
        """Next drive → host frame as (node, name, signals), or None; our own echoes are skipped."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            msg = self.bus.recv(left)
            if msg is None:
                return None
            if msg.is_remote_frame:
                continue
            try:
                message = self.db.get_message_by_frame_id(msg.arbitration_id)
            except KeyError:
                continue
            if not message.senders[0].startswith("ODrive"):
                continue
            node, name = message.name[4:].split("_", 1)
            return int(node), name, message.decode(bytes(msg.data), decode_choices=False)
        return None

    def collect(self, seconds: float, name: str | None = None) -> list:
        frames, deadline = [], time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            frame = self.receive(left)
            if frame and (name is None or frame[1] == name):
                frames.append(frame)
        return frames

    def wait_for(self, predicate, timeout: float):
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            frame = self.receive(left)
            if frame and predicate(*frame):
                return frame
        return None

    def arm(self) -> None:
        for node in NODES:
            self.send(node, "Clear_Errors", Identify=0)
            self.send(node, "Set_Controller_Mode", Control_Mode=TORQUE_CONTROL, Input_Mode=PASSTHROUGH)
            self.send(node, "Set_Axis_State", Axis_Requested_State=CLOSED_LOOP_CONTROL)

    def command_torque(self, torque: float) -> None:
        for node in NODES:
            self.send(node, "Set_Input_Torque", Input_Torque=torque)


@pytest.fixture
def client(ports):
    c = CanSimpleClient(ports["can_port"])
    try:
        yield c
    finally:
        c.close()


def latest_heartbeats(client: CanSimpleClient, timeout: float = 0.5) -> dict:
    beats, deadline = {}, time.monotonic() + timeout
    while len(beats) < len(NODES) and time.monotonic() < deadline:
        frame = client.receive(deadline - time.monotonic())
        if frame and frame[1] == "Heartbeat":
            beats[frame[0]] = frame[2]
    return beats


def test_public_cansimple_client_arms_drives_and_sees_the_watchdog_trip(robot, client):
    # Before arming: all axes IDLE, no errors, heartbeats arrive at ~10 Hz.
    beats = latest_heartbeats(client, timeout=2.0)
    assert {n: (b["Axis_State"], b["Axis_Error"]) for n, b in beats.items()} == {n: (IDLE, 0) for n in NODES}

    # Arm and drive: torque control, closed loop, 0.4 N·m on every wheel (a pure rotation),
    # a torque command every ~10 ms; drive for 0.6 s once every heartbeat reports CLOSED_LOOP_CONTROL.
    client.arm()
    start_turns = {}
    armed = set()
    give_up = time.monotonic() + 2.0
    armed_at = None
    while time.monotonic() < (armed_at + 0.6 if armed_at else give_up):
        client.command_torque(0.4)
        for node, name, sig in client.collect(0.01):
            if name == "Heartbeat" and sig["Axis_State"] == CLOSED_LOOP_CONTROL and sig["Axis_Error"] == 0:
                armed.add(node)
            if name == "Get_Encoder_Estimates":
                start_turns.setdefault(node, sig["Pos_Estimate"])
        if armed_at is None and armed == set(NODES):
            armed_at = time.monotonic()
    assert armed == set(NODES)

    # Cyclic encoder estimates show the wheels turning forwards (positive torque → positive velocity).
    cyclic = client.collect(0.05, "Get_Encoder_Estimates")
    client.command_torque(0.4)
    last = {node: sig for node, _, sig in cyclic}
    assert set(last) == set(NODES)
    for node in NODES:
        assert last[node]["Vel_Estimate"] > 0.5                    # turns/s
        assert last[node]["Pos_Estimate"] > start_turns[node] + 0.1

    # RTR polls: Get_Torques reports the commanded torque; Get_Encoder_Estimates is answered
    # (see test_rtr_poll_of_encoder_estimates_is_answered for a count that tells polls from cyclic frames).
    client.poll(1, "Get_Torques")
    reply = client.wait_for(lambda node, name, sig: node == 1 and name == "Get_Torques", 0.2)
    assert reply is not None
    assert reply[2]["Torque_Target"] == pytest.approx(0.4) and reply[2]["Torque_Estimate"] == pytest.approx(0.4)
    client.command_torque(0.4)
    client.poll(2, "Get_Encoder_Estimates")
    reply = client.wait_for(lambda node, name, sig: node == 2 and name == "Get_Encoder_Estimates", 0.2)
    assert reply is not None and reply[2]["Vel_Estimate"] > 0.5

    # Fall silent: the watchdogs expire (0.1 s) and the heartbeat reports it within ~0.3 s.
    client.command_torque(0.4)
    silent_since = time.monotonic()
    tripped = {}
    while len(tripped) < len(NODES) and time.monotonic() - silent_since < 1.0:
        frame = client.receive(0.05)
        if frame and frame[1] == "Heartbeat" and frame[2]["Axis_Error"] & WATCHDOG_TIMER_EXPIRED:
            assert frame[2]["Axis_State"] == IDLE
            tripped.setdefault(frame[0], time.monotonic() - silent_since)
    assert set(tripped) == set(NODES)
    assert max(tripped.values()) < 0.35

    client.poll(0, "Get_Error")
    error = client.wait_for(lambda node, name, sig: node == 0 and name == "Get_Error", 0.2)
    assert error[2]["Active_Errors"] == WATCHDOG_TIMER_EXPIRED and error[2]["Disarm_Reason"] == WATCHDOG_TIMER_EXPIRED

    # No torque: the robot coasts to rest on wheel friction.
    at_rest = set()
    deadline = time.monotonic() + 5.0
    while at_rest != set(NODES) and time.monotonic() < deadline:
        frame = client.receive(0.05)
        if frame and frame[1] == "Get_Encoder_Estimates":
            if abs(frame[2]["Vel_Estimate"]) < 0.01:
                at_rest.add(frame[0])
            else:
                at_rest.discard(frame[0])
    assert at_rest == set(NODES)

    assert robot.stop() == 0
    assert robot.summary()["watchdog_trips"] == 3


def scenario_with(tmp_path, robot_sim: str) -> str:
    text = (Path(__file__).resolve().parents[2] / "sharedctl" / "scenarios" / "paper_convex.toml").read_text()
    path = tmp_path / "scenario.toml"
    path.write_text(text + "\n[robot_sim]\n" + robot_sim + "\n")
    return str(path)


def test_rtr_poll_of_encoder_estimates_is_answered(tmp_path, ports, client):
    process = RobotProcess("--scenario", scenario_with(tmp_path, "encoder_rate_hz = 2"), **ports)
    try:
        process.wait_ready()
        client.collect(0.05)
        for _ in range(10):
            client.poll(1, "Get_Encoder_Estimates")
        frames = [f for f in client.collect(0.4, "Get_Encoder_Estimates") if f[0] == 1]
        assert len(frames) >= 10          # at most one of them is the 2 Hz cyclic frame
        assert frames[0][2] == {"Pos_Estimate": 0.0, "Vel_Estimate": 0.0}
    finally:
        assert process.stop() == 0


def test_bad_frames_are_counted_and_skipped(robot, client):
    set_torque = client.db.get_message_by_name("Axis0_Set_Input_Torque")
    nan_torque = bytes.fromhex("0000c07f00000000")                     # float32 NaN
    for data in (nan_torque, b"\x00\x00\x80"):                          # NaN; wrong DLC
        client.bus.send(can.Message(arbitration_id=set_torque.frame_id, data=data, is_extended_id=False))
    client.bus.send(can.Message(arbitration_id=0x1F, data=b"\x01", is_extended_id=False))   # unknown command
    client.poll(0, "Get_Torques")
    reply = client.wait_for(lambda node, name, sig: node == 0 and name == "Get_Torques", 0.5)
    assert reply is not None and reply[2]["Torque_Target"] == 0.0
    assert robot.stop() == 0
    assert robot.summary()["bad_frames"] == 3


def test_estop_and_clear_errors_over_the_bus(robot, client):
    client.arm()
    client.command_torque(0.0)
    client.send(0, "Estop")
    hb = client.wait_for(lambda node, name, sig: node == 0 and name == "Heartbeat" and sig["Axis_Error"], 0.5)
    assert hb[2]["Axis_Error"] == 0x2000000 and hb[2]["Axis_State"] == IDLE      # ESTOP_REQUESTED
    client.send(0, "Clear_Errors", Identify=0)
    hb = client.wait_for(lambda node, name, sig: node == 0 and name == "Heartbeat", 0.5)
    assert hb[2]["Axis_Error"] == 0 and hb[2]["Axis_State"] == IDLE


def test_sigterm_stops_the_process_within_two_seconds_with_exit_code_0_and_writes_its_summary(ports, tmp_path):
    process = RobotProcess(**ports, summary_path=tmp_path / "robot.json")
    try:
        process.wait_ready()
        time.sleep(0.3)
        process.proc.send_signal(signal.SIGTERM)
        started = time.monotonic()
        code = process.proc.wait(timeout=5)
        assert time.monotonic() - started < 2.0
        assert code == 0
        summary = process.summary()
        assert summary["physics_steps"] > 0 and summary["missed_ticks"] >= 0
        # the simulated time is its physics steps (1 kHz) and the stalls it skipped, nothing else
        assert summary["physics_steps"] * 1e-3 + summary["skipped_s"] == pytest.approx(summary["elapsed_s"], abs=1e-6)
    finally:
        process.stop()


def test_ground_truth_is_published_on_zenoh_from_the_initial_pose(robot):
    from sharedctl.protocol import keys
    from sharedctl.protocol.messages import GroundTruth
    from sharedctl.protocol.msgpack_codec import decode_message
    from sharedctl.protocol.wire_types import ROBOT_DIMS
    from sharedctl.services.zenoh_session import open_session

    received: queue.Queue = queue.Queue()
    session = open_session(connect=[robot.zenoh_endpoint])
    try:
        sub = session.declare_subscriber(keys.truth_key("robot1"), lambda s: received.put(s.payload.to_bytes()))
        alive = session.liveliness().get(keys.alive_key("robot1", "robot"), timeout=2.0)
        tokens = [reply.ok.key_expr for reply in alive if reply.ok is not None]
        messages = []
        deadline = time.monotonic() + 3.0
        while len(messages) < 20 and time.monotonic() < deadline:
            try:
                messages.append(decode_message(received.get(timeout=0.5), ROBOT_DIMS, expect=GroundTruth))
            except queue.Empty:
                pass
        sub.undeclare()
    finally:
        session.close()
    assert [str(k) for k in tokens] == [keys.alive_key("robot1", "robot")]
    assert len(messages) >= 20
    assert messages[-1].q == pytest.approx((-0.9, 3.0, 0.0))              # paper_convex [initial] q, at rest
    # never faster than 100 Hz: k messages after one, at least (k − 1) periods of simulated time have passed,
    # less a physics step for each end — what `Schedule` promises; one interval can be shorter than a period
    # (a send the loop reached late keeps the next on the period's grid), which a stall of this host causes.
    # The rate itself, and no burst after a stall: test_robot_simulation.py, on a synthetic clock; a stall
    # lengthens intervals here, so none is bounded from above.
    times = [m.time for m in messages]
    assert all(times[j] - times[i] >= (j - i - 1) * 0.01 - 2e-3 - 1e-9
               for i in range(len(times)) for j in range(i + 1, len(times)))
    assert all(b.seq == a.seq + 1 for a, b in zip(messages, messages[1:]))


def test_robot_sim_table_in_the_scenario_is_validated_at_start(tmp_path, ports):
    process = RobotProcess("--scenario", scenario_with(tmp_path, "friction_visc = 0.1"), **ports)
    try:
        assert process.proc.wait(timeout=20) == 2
    finally:
        process.stop()
    time.sleep(0.1)
    assert "robot_sim.friction_visc" in "".join(process.output)


@pytest.mark.skipif(not os.path.exists("/sys/class/net/vcan0"),
                    reason="no SocketCAN vcan0 on this host (kernel without CAN support); see deploy/vcan-setup.sh")
def test_socketcan_vcan0_heartbeats(ports):
    cmd = [sys.executable, "-m", "sharedctl.services.cli", "robot", "--can-interface", "socketcan",
           "--can-channel", "vcan0", "--zenoh-listen", f"tcp/127.0.0.1:{ports['zenoh_port']}", "--duration", "3"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        db = cantools.database.load_file(str(DBC_PATH))
        heartbeat = db.get_message_by_name("Axis0_Heartbeat")
        with can.Bus(interface="socketcan", channel="vcan0") as bus:
            deadline = time.monotonic() + 15
            seen = None
            while seen is None and time.monotonic() < deadline:
                msg = bus.recv(0.5)
                if msg is not None and msg.arbitration_id == heartbeat.frame_id and not msg.is_remote_frame:
                    seen = heartbeat.decode(bytes(msg.data), decode_choices=False)
        assert seen is not None and seen["Axis_State"] == IDLE
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)


class FakeBus:
    """Records what the process sends (no sockets)."""

    def __init__(self) -> None:
        self.sent: list[can.Message] = []

    def send(self, msg: can.Message, timeout=None) -> None:
        self.sent.append(msg)


def test_a_stall_of_the_simulator_does_not_trip_a_fed_watchdog():
    """Frames count from their receive timestamp, not from when the loop got round to them."""
    from sharedctl.models import OmniRobot
    from sharedctl.services.can_transport import Frame
    from sharedctl.services.robot.plant import RobotSimConfig
    from sharedctl.services.robot.process import RobotProcess as Shell
    from sharedctl.services.robot.simulation import RobotSimulation

    db = cantools.database.load_file(str(DBC_PATH))
    sim = RobotSimulation(OmniRobot(), RobotSimConfig(), [0, 0, 0], [0, 0, 0])
    shell = Shell(sim, FakeBus(), None, "robot1")
    wall0 = shell.wall_minus_monotonic + shell.clock_start        # wall-clock time of loop time 0

    def deliver(name, arrived, now, **signals):
        m = db.get_message_by_name(f"Axis0_{name}")
        data = bytes(m.encode(signals))
        shell.handle_message(Frame(m.frame_id, False, False, False, len(data), data, wall0 + arrived, None), now)

    deliver("Set_Controller_Mode", 0.0, 0.0, Control_Mode=TORQUE_CONTROL, Input_Mode=PASSTHROUGH)
    deliver("Set_Axis_State", 0.0, 0.0, Axis_Requested_State=CLOSED_LOOP_CONTROL)
    deliver("Set_Input_Torque", 0.08, 0.30, Input_Torque=0.2)    # arrived in time, handled after a 0.2 s stall
    deliver("Set_Input_Torque", 0.16, 0.30, Input_Torque=0.2)
    assert sim.axes[0].state == CLOSED_LOOP_CONTROL and sim.axes[0].errors == 0
    deliver("Set_Input_Torque", 0.29, 0.30, Input_Torque=0.2)    # arrived after the 0.1 s timeout
    assert sim.axes[0].state == IDLE and sim.axes[0].errors == WATCHDOG_TIMER_EXPIRED
