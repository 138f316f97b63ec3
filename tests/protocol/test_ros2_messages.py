"""RobotState → nav_msgs/msg/Odometry and std_msgs/msg/String, CDR → geometry_msgs/msg/Twist
(protocol/ros2_messages.py): what we encode, decoded by rosbags' deserializer and compared with values worked out
by hand; Twists built byte by byte."""
from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol_samples import state
from sharedctl.protocol.errors import BadCdr, NonFiniteValue, OutOfRange, ProtocolError
from sharedctl.protocol.messages import Authority
from sharedctl.protocol.ros2_messages import ODOMETRY, STRING, TWIST_BOUND, Ros2Codec, Twist, stamp

HALF = math.sqrt(0.5)
CODEC = Ros2Codec()


@pytest.fixture(scope="module")
def codec():
    return CODEC


@pytest.fixture(scope="module")
def jazzy():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def twist_bytes(*values: float, header: bytes = b"\x00\x01\x00\x00") -> bytes:
    """A Twist's CDR by hand: the little-endian encapsulation header, then six float64."""
    return header + struct.pack("<6d", *values)


def test_an_odometry_at_yaw_half_pi_decodes_with_rosbags_to_the_pose_and_the_body_velocity(codec, jazzy):
    """ψ = π/2: quaternion (0, 0, √½, √½); moving along world +y at 0.4 m/s is moving forward (body +x) at 0.4,
    along world −x at 0.1 is moving left (body +y) at 0.1."""
    s = state(time=1_700_000_000.25, q=(1.5, -2.0, math.pi / 2), qd_hat=(-0.1, 0.4, 0.3))
    odom = jazzy.deserialize_cdr(codec.odometry(s, "robot1"), ODOMETRY)
    assert (odom.header.stamp.sec, odom.header.stamp.nanosec) == (1_700_000_000, 250_000_000)
    assert (odom.header.frame_id, odom.child_frame_id) == ("robot1/odom", "robot1/base_link")
    p, o = odom.pose.pose.position, odom.pose.pose.orientation
    assert (p.x, p.y, p.z) == (1.5, -2.0, 0.0)
    assert (o.x, o.y, o.z, o.w) == pytest.approx((0.0, 0.0, HALF, HALF), abs=1e-15)
    lin, ang = odom.twist.twist.linear, odom.twist.twist.angular
    assert (lin.x, lin.y, lin.z) == pytest.approx((0.4, 0.1, 0.0), abs=1e-12)
    assert (ang.x, ang.y, ang.z) == (0.0, 0.0, 0.3)
    assert not odom.pose.covariance.any() and not odom.twist.covariance.any()


def test_an_odometry_at_yaw_zero_has_the_identity_quaternion(codec, jazzy):
    odom = jazzy.deserialize_cdr(codec.odometry(state(q=(0.0, 0.0, 0.0)), "r"), ODOMETRY)
    o = odom.pose.pose.orientation
    assert (o.x, o.y, o.z, o.w) == (0.0, 0.0, 0.0, 1.0)


def test_the_stamp_rounds_to_the_nanosecond_and_carries_into_the_second():
    assert stamp(12.9999999999) == (13, 0)
    assert stamp(3.5) == (3, 500_000_000)


@pytest.mark.parametrize("authority", list(Authority))
def test_the_authority_is_a_string_naming_who_drives(codec, jazzy, authority):
    assert jazzy.deserialize_cdr(codec.authority(state(authority=authority)), STRING).data == authority.value


def test_a_twist_written_byte_by_byte_decodes_to_its_components(codec):
    assert codec.twist(twist_bytes(0.3, -0.2, 0.0, 0.0, 0.0, 0.5)) == Twist((0.3, -0.2, 0.0), (0.0, 0.0, 0.5))


def test_a_big_endian_twist_decodes_too(codec):
    data = b"\x00\x00\x00\x00" + struct.pack(">6d", 1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    assert codec.twist(data) == Twist((1.0, 2.0, 3.0), (4.0, 5.0, 6.0))


@pytest.mark.parametrize("data", [b"", twist_bytes(0, 0, 0, 0, 0, 0)[:-1], twist_bytes(0, 0, 0, 0, 0, 0) + b"\x00",
                                  twist_bytes(0, 0, 0, 0, 0, 0, header=b"\x00\x07\x00\x00"), b"\xff" * 52])
def test_what_is_not_a_twists_cdr_is_bad_cdr(codec, data):
    with pytest.raises(BadCdr):
        codec.twist(data)


@pytest.mark.parametrize("values", [(math.nan, 0, 0, 0, 0, 0), (0, 0, 0, 0, 0, math.inf), (0, 0, -math.inf, 0, 0, 0)])
def test_a_twist_that_is_not_finite_is_refused(codec, values):
    with pytest.raises(NonFiniteValue):
        codec.twist(twist_bytes(*values))


@pytest.mark.parametrize("values", [(1e6, 0, 0, 0, 0, 0), (0, 0, 0, 0, 0, -101.0), (0, 0, 0, 200.0, 0, 0)])
def test_a_twist_no_robot_can_follow_is_out_of_range(codec, values):
    with pytest.raises(OutOfRange):
        codec.twist(twist_bytes(*values))


def test_what_we_encode_as_a_twist_rosbags_decodes(codec, jazzy):
    t = jazzy.deserialize_cdr(codec.twist_cdr(Twist((0.1, 0.2, 0.0), (0.0, 0.0, -0.4))), "geometry_msgs/msg/Twist")
    assert (t.linear.x, t.linear.y, t.angular.z) == (0.1, 0.2, -0.4)


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.binary(max_size=80), st.binary(min_size=48, max_size=48).map(lambda b: b"\x00\x01\x00\x00" + b),
                 st.tuples(st.sampled_from([b"\x00\x00\x00\x00", b"\x00\x01\x00\x00"]),
                           st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=6, max_size=6))
                 .map(lambda h: h[0] + struct.pack(("<" if h[0][1] else ">") + "6d", *h[1]))))
def test_any_payload_decodes_to_a_finite_bounded_twist_or_raises_a_typed_error(payload):
    try:
        twist = CODEC.twist(payload)
    except ProtocolError:
        return
    values = (*twist.linear, *twist.angular)
    assert all(math.isfinite(v) and abs(v) <= TWIST_BOUND for v in values)
