"""`kill -9` of a controller driving the real `sharedctl robot` process, then a fresh controller: the drives stay
disarmed until an operator takes control, and the pose it resumes from is the robot's (ground truth) within 1 cm.

The test is the operator (it publishes OperatorCommands, pushing all along as a console would) and listens on
the CAN bus; the ground truth is only for checking.
"""
from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol import keys
from sharedctl.protocol.messages import ControlRequest, GroundTruth, OperatorCommand, RobotState
from sharedctl.protocol.msgpack_codec import decode_message, encode_message
from sharedctl.protocol.odrive_enums import AxisState
from sharedctl.services import zenoh_session
from sharedctl.services.summary_output import read_json

from .processes import reap
from .test_controller_with_robot import BusListener, free_udp_port, wait_for

pytestmark = pytest.mark.processes


def test_a_controller_killed_while_driving_is_followed_by_one_that_resumes_the_pose_and_waits_for_a_take(tmp_path):
    port, z_robot = free_udp_port(), zenoh_session.free_loopback_port()
    z_ctrl = [zenoh_session.free_loopback_port(), zenoh_session.free_loopback_port()]
    common = ["--can-interface", "udp_multicast", "--can-option", f"port={port}", "--robot-id", "rtest"]
    cli = [sys.executable, "-m", "sharedctl.services.cli"]
    checkpoint = tmp_path / "controller.checkpoint"

    def controller(k, pose):
        return subprocess.Popen(cli + ["controller", *common, "--zenoh-listen", f"tcp/127.0.0.1:{z_ctrl[k]}", "--quiet",
                                       "--feedback-timeout-ms", "150", "--pose", pose, "--checkpoint", str(checkpoint),
                                       "--json", str(tmp_path / f"controller{k}.json")],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    listener = BusListener(port)
    listener.start()
    robot = ["nice", "-n", "-10", *cli, "robot", *common, "--zenoh-listen", f"tcp/127.0.0.1:{z_robot}"]
    procs = [subprocess.Popen(robot, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)]
    sessions = []
    states, truths = [], []

    def connect(k):
        """A session on the robot and controller k: its states into `states`, its commands from `pub`."""
        wait_for(lambda: _listening(z_ctrl[k]), 20.0, f"controller {k} listening")
        session = zenoh_session.open_session(connect=[f"tcp/127.0.0.1:{z_robot}", f"tcp/127.0.0.1:{z_ctrl[k]}"])
        sessions.append(session)
        states.clear()
        session.declare_subscriber(keys.state_key("rtest"),
                                   lambda s: states.append(decode_message(s.payload.to_bytes(), expect=RobotState)))
        if k == 0:
            session.declare_subscriber(keys.truth_key("rtest"), lambda s: truths.append(
                decode_message(s.payload.to_bytes(), expect=GroundTruth)))
        return session.declare_publisher(keys.operator_cmd_key("rtest"))

    try:
        procs.append(controller(0, "scenario"))
        pub = connect(0)
        seq = 0

        def push(seconds, request=ControlRequest.NONE):
            nonlocal seq
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                seq += 1
                pub.put(encode_message(OperatorCommand(
                    operator_id="op", session_id="r1", seq=seq, send_time=time.time(), joystick=(0.0, 0.6, 0.0),
                    q_d=tuple(truths[-1].q), qd_d=(0.0, 0.0, 0.0), qdd_d=(0.0, 0.0, 0.0), deadman=True, estop=False,
                    control_request=request)))
                time.sleep(0.02)

        wait_for(listener.armed, 20.0, "the first controller to arm the drives")
        wait_for(lambda: len(truths) > 5 and len(states) > 5, 10.0, "telemetry and ground truth")
        q_start = np.array(truths[-1].q)
        push(1.5)
        assert np.linalg.norm(truths[-1].qd) > 0.05                       # killed while moving
        procs[1].send_signal(signal.SIGKILL)
        procs[1].wait(timeout=5)
        push(1.0)                                                         # the operator keeps pushing
        moved = np.array(truths[-1].q) - q_start
        assert np.linalg.norm(moved) > 0.1, moved                         # far from the scenario's start pose

        restarted_at = time.monotonic()
        procs.append(controller(1, "checkpoint"))
        pub = connect(1)
        wait_for(lambda: len(states) > 5, 10.0, "the second controller's telemetry")
        push(1.5)                                                         # commands, but no take
        closed = [f for _, f in listener.frames(cs.SetAxisState, since=restarted_at)
                  if f.requested_state is AxisState.CLOSED_LOOP_CONTROL]
        assert closed == [] and listener.frames(cs.ClearErrors, since=restarted_at) == []
        assert not listener.armed() and states[-1].estop_active
        wait_for(lambda: np.linalg.norm(truths[-1].qd) < 1e-3, 10.0, "the robot at rest")
        time.sleep(0.1)
        error = np.linalg.norm(np.array(states[-1].q[:2]) - np.array(truths[-1].q[:2]))
        assert error < 0.01, (states[-1].q, truths[-1].q)
        assert abs(states[-1].q[2] - truths[-1].q[2]) < 0.01

        push(1.0, request=ControlRequest.TAKE)                            # the operator takes control
        wait_for(listener.armed, 10.0, "the drives armed after the operator's take")
        assert not states[-1].estop_active
        procs[2].send_signal(signal.SIGTERM)
        assert procs[2].wait(timeout=5) == 0
        assert "resumed from a checkpoint" in read_json(tmp_path / "controller1.json")["start"]
    finally:
        for session in sessions:
            session.close()
        reap(procs)
        listener.stop()


def _listening(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False
