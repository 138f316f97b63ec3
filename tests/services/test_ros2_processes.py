"""`--ros2` with real processes: what a ROS 2 machine on rmw_zenoh would see and send, played by a plain Zenoh
client that decodes with rosbags and writes Twists byte by byte with rmw_zenoh's attachment.

1. `sharedctl demo --headless --zenoh-listen tcp/127.0.0.1:PORT --ros2 0`: the Odometry on rmw_zenoh's key for
   `/robot1/odom` carries the pose of the RobotState with the same time (within 1 cm); the node's and its
   entities' liveliness tokens have the design document's shape; a Twist on `/robot1/cmd_vel` while the
   scripted console holds the lease is refused (`not_holder` in the controller's summary) and the run is
   undisturbed.
2. robot + controller without a console (implicit lease): the Twist sender takes control and the robot's ground
   truth moves forward, as commanded.
"""
from __future__ import annotations

import json
import re
import socket
import struct
import subprocess
import sys
import time

import numpy as np
import pytest

from sharedctl.protocol import keys
from sharedctl.protocol import rmw_zenoh as rmw
from sharedctl.protocol.messages import GroundTruth, RobotState
from sharedctl.protocol.msgpack_codec import decode_message
from sharedctl.services import zenoh_session

from .processes import reap, wait_for

pytestmark = pytest.mark.processes
CLI = [sys.executable, "-m", "sharedctl.services.cli"]
ODOM, TWIST = "nav_msgs/msg/Odometry", "geometry_msgs/msg/Twist"
GID = bytes.fromhex("5e" * 16)


def jazzy():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def listening(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


def twist_sample(seq: int, vx: float) -> tuple[bytes, bytes]:
    """A forward Twist's CDR by hand and rmw_zenoh's attachment (seq, source time in ns, GID length, GID)."""
    return (b"\x00\x01\x00\x00" + struct.pack("<6d", vx, 0.0, 0.0, 0.0, 0.0, 0.0),
            struct.pack("<qqB", seq, time.time_ns(), 16) + GID)


def test_the_demo_publishes_odometry_of_its_robot_state_and_refuses_a_twist_while_the_console_drives(tmp_path):
    port = zenoh_session.free_loopback_port()
    out, logs = tmp_path / "demo.json", tmp_path / "logs"
    demo = subprocess.Popen(CLI + ["demo", "--headless", "--duration", "4", "--no-reference",
                                   "--feedback-timeout-ms", "150", "--zenoh-listen", f"tcp/127.0.0.1:{port}",
                                   "--ros2", "0", "--json", str(out), "--log-dir", str(logs)],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    session = None
    store = jazzy()
    odoms, states = [], []
    try:
        wait_for(lambda: listening(port) or demo.poll() is not None, 30.0, "the controller's endpoint")
        session = zenoh_session.open_session(connect=[f"tcp/127.0.0.1:{port}"])
        session.declare_subscriber(rmw.topic_key(0, "/robot1/odom", ODOM),
                                   lambda s: odoms.append((s.payload.to_bytes(), s.attachment.to_bytes())))
        session.declare_subscriber(keys.state_key("robot1"),
                                   lambda s: states.append(decode_message(s.payload.to_bytes(), expect=RobotState)))
        wait_for(lambda: states and states[-1].lease_holder == "operator", 30.0, "the console holding the lease")
        tokens = [str(reply.ok.key_expr) for reply in session.liveliness().get("@ros2_lv/0/**", timeout=2.0)]
        cmd_vel = session.declare_publisher(rmw.topic_key(0, "/robot1/cmd_vel", TWIST))
        for seq in range(1, 41):                                       # 0.8 s of full-speed forward at 50 Hz
            payload, attachment = twist_sample(seq, 0.5)
            cmd_vel.put(payload, attachment=attachment)
            time.sleep(0.02)
        demo.wait(timeout=60)
    finally:
        if session is not None:
            session.close()
        reap([demo])
    summary = json.loads(out.read_text())
    assert demo.returncode == 0 and summary["ok"], demo.stdout.read()[-3000:]

    # the Odometry is the RobotState of the same instant
    by_time = {round(s.time * 1e6): s for s in states}
    matched = 0
    for payload, _ in odoms:
        odom = store.deserialize_cdr(payload, ODOM)
        t = odom.header.stamp.sec * 1_000_000 + round(odom.header.stamp.nanosec / 1000)
        state = by_time.get(t)
        if state is None:
            continue
        matched += 1
        p, o = odom.pose.pose.position, odom.pose.pose.orientation
        assert np.hypot(p.x - state.q[0], p.y - state.q[1]) < 0.01
        assert 2 * np.arctan2(o.z, o.w) == pytest.approx(state.q[2], abs=1e-6)
    assert matched > 50, (len(odoms), len(states))
    attachments = [rmw.Attachment.decode(a) for _, a in odoms]
    seqs = [a.sequence_number for a in attachments]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))         # the attachment counts every publication
    assert len({a.gid for a in attachments}) == 1                    # from one publisher

    # the node and its entities, as the design document shapes them (one session id for all)
    shape = re.compile(r"@ros2_lv/0/(?P<zid>[0-9a-f]{1,32})/0/(?P<eid>[0-3])/(?P<kind>NN|MP|MS)/%/%robot1/"
                       r"sharedctl_controller(?P<topic>/.*)?")
    found = {m["eid"]: m for m in map(shape.fullmatch, tokens) if m}
    assert sorted(found) == ["0", "1", "2", "3"] and len({m["zid"] for m in found.values()}) == 1, tokens
    assert found["3"]["kind"] == "MS" and found["3"]["topic"] == (
        f"/%robot1%cmd_vel/geometry_msgs::msg::dds_::Twist_/{rmw.TYPE_HASHES[TWIST]}/::,10:,:,:,,")
    assert found["1"]["topic"].startswith("/%robot1%odom/nav_msgs::msg::dds_::Odometry_/")

    # the Twists were heard and refused: the console held control
    controller = summary["processes"]["controller"]["summary"]
    ros2 = controller["ros2"]
    assert ros2["twists_received"] == 40 and ros2["twists_accepted"] == 0, ros2
    assert ros2["twists_refused"] == {"not_holder": 40} and controller["rejections"]["not_holder"] >= 40
    # odometry and authority go out in the two periods after each RobotState: a controller stopped between them
    # has sent the last state's odometry and not yet its authority
    assert ros2["odom_sent"] > 40 * 4 and ros2["authority_sent"] in (ros2["odom_sent"], ros2["odom_sent"] - 1)
    assert summary["violations"] == 0 and summary["estops"] == 0


@pytest.fixture
def robot_and_controller(tmp_path):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("", 0))
        can_port = s.getsockname()[1]
    z_robot, z_ctrl = zenoh_session.free_loopback_port(), zenoh_session.free_loopback_port()
    can = ["--can-interface", "udp_multicast", "--can-option", f"port={can_port}", "--robot-id", "rtest"]
    summary = tmp_path / "controller.json"
    procs = [subprocess.Popen(["nice", "-n", "-10", *CLI, "robot", *can, "--zenoh-listen", f"tcp/127.0.0.1:{z_robot}"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True),
             subprocess.Popen(CLI + ["controller", *can, "--zenoh-listen", f"tcp/127.0.0.1:{z_ctrl}", "--quiet",
                                     "--feedback-timeout-ms", "150", "--checkpoint", "none", "--ros2",
                                     "--json", str(summary)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)]
    session = None
    try:
        wait_for(lambda: listening(z_robot) and listening(z_ctrl), 30.0, "robot and controller listening")
        session = zenoh_session.open_session(connect=[f"tcp/127.0.0.1:{z_robot}", f"tcp/127.0.0.1:{z_ctrl}"])
        yield procs, session, summary
    finally:
        if session is not None:
            session.close()
        reap(procs)


def test_a_twist_sender_that_takes_the_free_lease_moves_the_robot_forward(robot_and_controller):
    procs, session, summary = robot_and_controller
    states, truths = [], []
    session.declare_subscriber(keys.state_key("rtest"),
                               lambda s: states.append(decode_message(s.payload.to_bytes(), expect=RobotState)))
    session.declare_subscriber(keys.truth_key("rtest"),
                               lambda s: truths.append(decode_message(s.payload.to_bytes(), expect=GroundTruth)))
    wait_for(lambda: len(truths) > 5 and states and not states[-1].estop_active
             and states[-1].link.can_feedback_age_ms < 50, 30.0, "the robot armed and reporting")
    time.sleep(0.5)                                                    # armed: the drives in closed loop
    start = np.array(truths[-1].q)
    assert start[2] == pytest.approx(0.0, abs=0.01)                   # ψ = 0: forward is world +x
    cmd_vel = session.declare_publisher(rmw.topic_key(0, "/rtest/cmd_vel", TWIST))
    for seq in range(1, 76):                                           # 1.5 s at 0.3 m/s (0.6 of full scale)
        payload, attachment = twist_sample(seq, 0.3)
        cmd_vel.put(payload, attachment=attachment)
        time.sleep(0.02)
    holder = states[-1].lease_holder
    moved = np.array(truths[-1].q) - start
    procs[1].terminate()
    assert procs[1].wait(timeout=5) == 0
    assert holder == "ros2-" + GID.hex()
    assert moved[0] > 0.05 and abs(moved[1]) < 0.3 * moved[0], moved   # forward, along world +x
    ros2 = json.loads(summary.read_text())["ros2"]
    assert ros2["twists_accepted"] == 75 and ros2["twists_refused"] == {}
