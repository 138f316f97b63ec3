"""`sharedctl console --script` as a process against a stand-in controller (a Zenoh peer in the test)."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from sharedctl.protocol import keys
from sharedctl.protocol.messages import (Authority, LeaseReply, LeaseRequest, LinkHealth, OperatorCommand, RobotState,
                                         SetClass)
from sharedctl.protocol.msgpack_codec import decode_message, encode_message
from sharedctl.protocol.wire_types import ROBOT_DIMS
from sharedctl.services.scenario_files import load
from sharedctl.services.zenoh_session import free_loopback_port, open_session

pytestmark = pytest.mark.processes   # real processes / sockets: never in a parallel worker

POSE = (-0.8, 2.9, 0.0)
VELOCITY = (0.05, -0.1, 0.0)


def robot_state(seq: int) -> RobotState:
    z = (0.0, 0.0, 0.0)
    return RobotState(
        seq=seq, time=seq * 0.02, q=POSE, qd_hat=VELOCITY, q_ref=POSE, group_classes=(SetClass.SAFE,),
        active_group=None, authority=Authority.HUMAN, k_s=1.0, k_h=1.0, k_f=0.0, u_h=z, u_f=z, u_s=z,
        wheel_torques=z, theta_hat=z, min_margin=0.1, region_margins=(0.1,), estop_active=False,
        lease_holder=None, link=LinkHealth(operator_latency_ms=0.0, loss_fraction=0.0, staleness_ms=0.0,
                                           can_feedback_age_ms=0.0),
    )


@pytest.fixture(scope="module")
def console_run():
    """A stand-in controller publishing RobotState at 50 Hz for 3 s; the console's commands, exit code and stop time."""
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    session = open_session(listen=[endpoint])
    received = []
    sub = session.declare_subscriber(
        keys.operator_cmd_key("robot1"),
        lambda s: received.append((time.monotonic(),
                                   decode_message(s.payload.to_bytes(), ROBOT_DIMS, expect=OperatorCommand))))
    pub = session.declare_publisher(keys.state_key("robot1"))
    lease_requests = []

    def grant(query):                     # the stand-in controller's lease queryable: every take is granted
        request = decode_message(query.payload.to_bytes(), None, expect=LeaseRequest)
        lease_requests.append(request)
        query.reply(keys.lease_key("robot1"), encode_message(LeaseReply(
            request_seq=request.seq, time=time.time(), granted=True, holder=request.operator_id, reason="granted")))

    queryable = session.declare_queryable(keys.lease_key("robot1"), grant)
    proc = subprocess.Popen(
        [sys.executable, "-m", "sharedctl.services.cli", "console", "--script", "paper_convex", "--headless",
         "--zenoh-connect", endpoint], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 20.0
        seq = 0
        first_state = None
        while time.monotonic() < deadline:
            seq += 1
            pub.put(encode_message(robot_state(seq), ROBOT_DIMS))
            first_state = first_state or time.monotonic()
            if len(received) >= 150:
                break
            time.sleep(0.02)
        proc.send_signal(signal.SIGTERM)
        sent = time.monotonic()
        proc.wait(timeout=10)
        stop_seconds = time.monotonic() - sent
        output = proc.stdout.read().decode()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        sub.undeclare()
        pub.undeclare()
        queryable.undeclare()
        session.close()
    return {"lease_requests": lease_requests, "commands": [c for _, c in received],
            "arrivals": [a for a, _ in received], "exit": proc.returncode, "stop_seconds": stop_seconds,
            "output": output, "pid": proc.pid}


def test_the_console_sends_commands_once_telemetry_arrives(console_run):
    assert len(console_run["commands"]) >= 150


def test_the_console_takes_control_before_it_commands(console_run):
    requests = console_run["lease_requests"]
    assert requests and requests[0].action.value == "take"
    assert requests[0].session_id == console_run["commands"][0].session_id


def test_the_command_rate_is_50_hz(console_run):
    arrivals = np.array(console_run["arrivals"])
    rate = (len(arrivals) - 1) / (arrivals[-1] - arrivals[0])
    assert 40.0 < rate < 60.0


def test_sequence_numbers_increase_by_one_within_one_session(console_run):
    commands = console_run["commands"]
    assert len({c.session_id for c in commands}) == 1
    assert [c.seq for c in commands] == list(range(commands[0].seq, commands[0].seq + len(commands)))


def test_the_deflection_is_the_scripted_operators_at_the_telemetry_pose(console_run):
    human = load("paper_convex").closed_loop()[0].human
    q, v = np.array(POSE), np.array(VELOCITY)
    for cmd in console_run["commands"][::25]:
        t = float(np.clip((cmd.q_d[1] - 2.0) / 0.15, 0.0, None))   # the line's y_d = 2 + 0.15 t gives the script time
        assert np.allclose(cmd.joystick, np.clip(human.command(t, q, v).deflection, -1, 1), atol=1e-9)
        assert cmd.deadman and not cmd.estop


def test_sigterm_ends_the_console_with_exit_0_within_2_s(console_run):
    assert console_run["exit"] == 0
    assert console_run["stop_seconds"] < 2.0
    assert "sharedctl console: script robot1: sent" in console_run["output"]


def test_no_console_process_is_left_behind(console_run):
    with pytest.raises(ProcessLookupError):
        os.kill(console_run["pid"], 0)
