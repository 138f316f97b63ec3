"""`controller --ros2 DOMAIN`: the controller as a ROS 2 node over rmw_zenoh, on the controller's Zenoh session.

What a ROS 2 (Jazzy) machine with `RMW_IMPLEMENTATION=rmw_zenoh_cpp` sees (protocol/rmw_zenoh.py for the
formats, protocol/ros2_messages.py for the messages), node `/<robot>/sharedctl_controller`:

    /<robot>/odom       nav_msgs/msg/Odometry     published at the telemetry rate (RobotState's)
    /<robot>/authority  std_msgs/msg/String       published at the telemetry rate: human | shared | machine
    /<robot>/cmd_vel    geometry_msgs/msg/Twist   subscribed: operator input (twist_input.py)

Liveliness tokens for the node and the three entities are declared at start and held for as long as the
daemon runs (`undeclare` at exit). Every sample put carries rmw_zenoh's attachment (sequence number,
source timestamp, the publisher's GID).

Timing: Odometry and authority are built, encoded and put from the RobotState of the telemetry schedule,
each in a period of its own after the RobotState's own three (telemetry_schedule.py `followers`), on the
loop thread — no other thread takes the GIL for them. Twists wait in a Zenoh FIFO channel that the loop
polls with the operator commands (a `CommandIntake`, command_intake.py: no callback thread); before the
loop's first read of the pose they stay in the channel.
"""
from __future__ import annotations

import time

from sharedctl.protocol import rmw_zenoh as rmw
from sharedctl.protocol.ros2_messages import ODOMETRY, STRING, TWIST, Ros2Codec

from .. import zenoh_qos
from . import command_intake
from .command_intake import CommandIntake
from .twist_input import TwistInput, TwistScale

NODE = "sharedctl_controller"
NODE_ID, ODOM_ID, AUTHORITY_ID, CMD_VEL_ID = 0, 1, 2, 3     # ids within the session (rmw_zenoh counts them so)
QOS = rmw.Qos(depth=10)                                       # reliable, volatile, keep last 10


class Ros2Publisher:
    """A Zenoh publisher on a topic's key that puts each payload with rmw_zenoh's attachment."""

    def __init__(self, session, key: str, gid: bytes) -> None:
        self.publisher = zenoh_qos.declare_publisher(session, key, zenoh_qos.ROS2_KEEP_LAST)
        self.key, self.gid = key, gid
        self.seq = 0

    def put(self, payload: bytes) -> None:
        self.seq += 1
        self.publisher.put(payload, attachment=rmw.Attachment(self.seq, time.time_ns(), self.gid).encode())


class TwistIntake(CommandIntake):
    """Twists from their channel to `TwistInput`; nothing before the loop has read the pose once."""

    def apply(self) -> None:
        if self.policy.policy.pose is not None:
            super().apply()


class Ros2Links:
    """The ROS 2 node of robot `robot_id`'s controller in ROS domain `domain`, on `session`."""

    def __init__(self, session, robot_id: str, domain: int, policy, scale: TwistScale | None = None,
                 codec: Ros2Codec | None = None) -> None:
        self.robot_id, self.domain = robot_id, rmw.check_domain(domain)
        self.node = f"/{robot_id}/{NODE}"
        self.codec = codec or Ros2Codec()
        zid = str(session.info.zid())
        namespace = f"/{rmw.check_token(robot_id, 'robot id (a ROS 2 namespace here)')}"
        topics = {name: rmw.fully_qualified(robot_id, name) for name in ("odom", "authority", "cmd_vel")}
        entity = lambda eid, kind, name, ros_type: rmw.entity_token(   # noqa: E731 — four of a kind
            domain, zid, NODE_ID, eid, kind, namespace, NODE, topics[name], ros_type, QOS)
        self.tokens = {
            "node": rmw.node_token(domain, zid, NODE_ID, namespace, NODE),
            "odom": entity(ODOM_ID, rmw.EntityKind.PUBLISHER, "odom", ODOMETRY),
            "authority": entity(AUTHORITY_ID, rmw.EntityKind.PUBLISHER, "authority", STRING),
            "cmd_vel": entity(CMD_VEL_ID, rmw.EntityKind.SUBSCRIPTION, "cmd_vel", TWIST),
        }
        self.keys = {"odom": rmw.topic_key(domain, topics["odom"], ODOMETRY),
                     "authority": rmw.topic_key(domain, topics["authority"], STRING),
                     "cmd_vel": rmw.topic_key(domain, topics["cmd_vel"], TWIST)}
        self.odom = Ros2Publisher(session, self.keys["odom"], rmw.gid_of(self.tokens["odom"]))
        self.authority = Ros2Publisher(session, self.keys["authority"], rmw.gid_of(self.tokens["authority"]))
        self.subscriber = session.declare_subscriber(self.keys["cmd_vel"], command_intake.channel())
        self.twists = TwistInput(policy, self.codec, scale or TwistScale())
        self.intake = TwistIntake(self.subscriber, self.twists)
        liveliness = session.liveliness()
        self.liveliness = [liveliness.declare_token(token) for token in self.tokens.values()]

    # the telemetry schedule's followers (telemetry_schedule.py): one RobotState, one period each
    def send_odometry(self, state, now: float) -> None:
        self.odom.put(self.codec.odometry(state, self.robot_id))

    def send_authority(self, state, now: float) -> None:
        self.authority.put(self.codec.authority(state))

    def summary(self) -> dict:
        t = self.twists
        return {"domain": self.domain, "node": self.node, "keys": dict(self.keys),
                "odom_sent": self.odom.seq, "authority_sent": self.authority.seq,
                "twists_received": t.received, "twists_accepted": t.accepted, "twists_refused": dict(t.refused)}

    def undeclare(self) -> None:
        for entity in (self.subscriber, self.odom.publisher, self.authority.publisher, *self.liveliness):
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 — closing anyway
                pass
