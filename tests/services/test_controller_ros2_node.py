"""The daemon as a ROS 2 node (services/controller/ros2_links.py), stepped by hand on an in-memory session: its
liveliness tokens and keys, the Odometry and authority in their own telemetry periods after the RobotState's
three, decoded with rosbags; Twists from the cmd_vel channel judged when the loop polls, never before it has
read the pose."""
from __future__ import annotations

import math
import struct
import time

import pytest

from sharedctl.protocol import rmw_zenoh as rmw
from sharedctl.protocol.messages import RobotState
from sharedctl.protocol.msgpack_codec import decode_message
from sharedctl.services.controller.daemon import ControllerDaemon, DaemonConfig
from sharedctl.services.scenario_files import load

from .test_controller_loop import MemoryBus, MemorySession, Publisher, arm, start
from .zenoh_fakes import Sample

ZID = "c99b3b4b5e2d544a0a12a453bb95d921"
HASH = rmw.TYPE_HASHES


class RosPublisher(Publisher):
    def put(self, payload, attachment=None):
        self.payloads.append((payload, attachment))


class RosSession(MemorySession):
    """The in-memory session with a session id, publishers that keep attachments, and the tokens declared."""

    def __init__(self):
        super().__init__()
        self.tokens = []
        self.info = self

    def zid(self):
        return ZID

    def declare_publisher(self, key, **qos):
        return self.publishers.setdefault(key, RosPublisher())

    def declare_token(self, key):
        self.tokens.append(key)
        return Publisher()


@pytest.fixture
def daemon():
    loop, q0, _ = load("paper_convex").closed_loop("ce")
    d = ControllerDaemon(DaemonConfig(robot_id="unit", verbose=False, ros2_domain=3), loop, q0, MemoryBus(),
                         RosSession())
    d.master.clock = lambda: d.clock_now
    d.clock_now = 10.0
    return d


def test_the_node_and_its_three_entities_hold_the_design_documents_tokens(daemon):
    qos = "::,10:,:,:,,"
    assert daemon.session.tokens[1:] == [   # after the controller's own …/alive/controller
        f"@ros2_lv/3/{ZID}/0/0/NN/%/%unit/sharedctl_controller",
        f"@ros2_lv/3/{ZID}/0/1/MP/%/%unit/sharedctl_controller/%unit%odom/nav_msgs::msg::dds_::Odometry_/"
        f"{HASH['nav_msgs/msg/Odometry']}/{qos}",
        f"@ros2_lv/3/{ZID}/0/2/MP/%/%unit/sharedctl_controller/%unit%authority/std_msgs::msg::dds_::String_/"
        f"{HASH['std_msgs/msg/String']}/{qos}",
        f"@ros2_lv/3/{ZID}/0/3/MS/%/%unit/sharedctl_controller/%unit%cmd_vel/geometry_msgs::msg::dds_::Twist_/"
        f"{HASH['geometry_msgs/msg/Twist']}/{qos}",
    ]
    assert f"3/unit/odom/nav_msgs::msg::dds_::Odometry_/{HASH['nav_msgs/msg/Odometry']}" in daemon.session.publishers
    assert (f"3/unit/cmd_vel/geometry_msgs::msg::dds_::Twist_/{HASH['geometry_msgs/msg/Twist']}"
            in daemon.session.subscriptions)


def test_odometry_and_authority_go_out_in_the_two_periods_after_the_robot_state_with_its_values(daemon):
    from rosbags.typesys import Stores, get_typestore

    jazzy = get_typestore(Stores.ROS2_JAZZY)
    start(daemon)
    arm(daemon)
    pubs = daemon.session.publishers
    states = pubs["sharedctl/v1/unit/state"].payloads
    odom = pubs[daemon.ros2.keys["odom"]].payloads
    authority = pubs[daemon.ros2.keys["authority"]].payloads
    for stage in range(3):
        daemon.telemetry.stage(stage, 20.0 + 0.002 * stage)
    assert len(states) == 1 and odom == [] and authority == []
    daemon.telemetry.stage(3, 20.006)
    assert len(odom) == 1 and authority == []
    daemon.telemetry.stage(4, 20.008)
    assert len(authority) == 1
    state = decode_message(states[0][0], expect=RobotState)
    message = jazzy.deserialize_cdr(odom[0][0], "nav_msgs/msg/Odometry")
    p = message.pose.pose.position
    assert (p.x, p.y) == state.q[:2]
    assert message.pose.pose.orientation.z == pytest.approx(math.sin(state.q[2] / 2))
    assert message.header.stamp.sec + message.header.stamp.nanosec * 1e-9 == pytest.approx(state.time, abs=1e-9)
    assert jazzy.deserialize_cdr(authority[0][0], "std_msgs/msg/String").data == state.authority.value
    meta = rmw.Attachment.decode(odom[0][1])
    assert meta.sequence_number == 1 and meta.gid == rmw.gid_of(daemon.session.tokens[2])


def test_the_schedule_runs_its_five_stages_in_a_telemetry_period(daemon):
    start(daemon)
    arm(daemon)
    odom = daemon.session.publishers[daemon.ros2.keys["odom"]].payloads
    for k in range(500):                                           # 1 s at 500 Hz
        daemon.telemetry.states(30.0 + 0.002 * k)
    assert len(odom) in (49, 50, 51)
    assert [rmw.Attachment.decode(a).sequence_number for _, a in odom] == list(range(1, len(odom) + 1))


def test_a_twist_waits_for_the_loops_first_pose_then_drives_through_the_policy(daemon):
    sub = daemon.session.subscriptions[daemon.ros2.keys["cmd_vel"]]
    sample = Sample(b"\x00\x01\x00\x00" + struct.pack("<6d", 0.25, 0.0, 0.0, 0.0, 0.0, 0.0), "",
                    struct.pack("<qqB", 1, time.time_ns(), 16) + bytes(16))
    sub.samples.append(sample)
    daemon.apply_commands()                                         # no pose read yet: the Twist waits
    assert sub.samples == [sample] and daemon.ros2.twists.received == 0
    start(daemon)                                                  # the first tick reads the pose
    assert daemon.ros2.twists.accepted == 1 and sub.samples == []
    assert daemon.policy.lease.holder_id == "ros2-" + bytes(16).hex()
    assert daemon.policy.current.joystick == pytest.approx((0.5, 0.0, 0.0))
