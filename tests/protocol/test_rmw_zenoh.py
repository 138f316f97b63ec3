"""rmw_zenoh's key expressions, liveliness tokens and attachment (protocol/rmw_zenoh.py), against the literal
examples of rmw_zenoh's design document (ros2/rmw_zenoh, docs/design.md), rosbags' Jazzy typestore (the type
hashes) and zenoh's own serialiser (the attachment)."""
from __future__ import annotations

import struct

import pytest
import zenoh.ext
from hypothesis import given
from hypothesis import strategies as st

from sharedctl.protocol import rmw_zenoh as rmw
from sharedctl.protocol.errors import BadAttachment, KeyExprError

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"   # the design document's


# ---------------------------------------------------------------- the design document's examples
def test_the_topic_key_of_chatter_is_the_design_documents():
    assert (rmw.topic_key(0, "/chatter", "std_msgs/msg/String")
            == f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")


def test_a_namespace_is_part_of_the_topic_key_as_in_the_design_document():
    assert (rmw.topic_key(0, "/robot1/chatter", "std_msgs/msg/String")
            == f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")


def test_the_node_token_is_the_design_documents_listener():
    assert (rmw.node_token(2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "/", "listener")
            == "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener")


def test_the_subscription_token_is_the_design_documents_listener_on_chatter():
    token = rmw.entity_token(2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, 10, rmw.EntityKind.SUBSCRIPTION, "/",
                             "listener", "/chatter", "std_msgs/msg/String", rmw.Qos(depth=10))
    assert token == ("@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/"
                     f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,10:,:,:,,")


def test_the_publisher_token_is_the_design_documents_talker_with_depth_7():
    token = rmw.entity_token(2, "8b20917502ee955ac4476e0266340d5c", 0, 10, rmw.EntityKind.PUBLISHER, "/",
                             "talker", "/chatter", "std_msgs/msg/String", rmw.Qos(depth=7))
    assert token == ("@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
                     f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,")


# ---------------------------------------------------------------- what the design document describes
def test_a_namespace_and_a_qualified_name_are_mangled_slash_by_slash():
    token = rmw.entity_token(0, "c99b3b4b", 0, 1, rmw.EntityKind.PUBLISHER, "/robot1", "sharedctl_controller",
                             "/robot1/odom", "nav_msgs/msg/Odometry")
    parts = token.split("/")
    assert parts[:9] == ["@ros2_lv", "0", "c99b3b4b", "0", "1", "MP", "%", "%robot1", "sharedctl_controller"]
    assert parts[9:11] == ["%robot1%odom", "nav_msgs::msg::dds_::Odometry_"]
    assert len(parts) == 13          # rmw_zenoh's parser wants exactly these 13 chunks for an entity


@pytest.mark.parametrize("qos, text", [
    (rmw.Qos(rmw.Reliability.RELIABLE, rmw.Durability.VOLATILE, rmw.History.KEEP_LAST, 42), "::,:,:,:,,"),
    (rmw.Qos(rmw.Reliability.BEST_EFFORT, rmw.Durability.TRANSIENT_LOCAL, rmw.History.KEEP_ALL, 5), "2:1:2,5:,:,:,,"),
])
def test_the_qos_leaves_rmw_zenohs_defaults_empty(qos, text):
    """qos_to_keyexpr: reliable, volatile, keep-last, depth 42 are rmw_zenoh's defaults (qos.cpp)."""
    assert qos.keyexpr() == text


def test_the_type_name_is_the_dds_one():
    assert rmw.dds_type_name("geometry_msgs/msg/Twist") == "geometry_msgs::msg::dds_::Twist_"


@pytest.mark.parametrize("bad", ["robot-1", "1robot", "a__b", "a/b", "", "ünï"])
def test_a_name_that_is_no_ros_name_token_is_refused(bad):
    with pytest.raises(KeyExprError):
        rmw.fully_qualified(bad, "odom")


@pytest.mark.parametrize("domain", [-1, 233, 1.0, True, "0"])
def test_a_domain_outside_0_to_232_is_refused(domain):
    with pytest.raises(KeyExprError):
        rmw.topic_key(domain, "/chatter", "std_msgs/msg/String")


# ---------------------------------------------------------------- Jazzy type hashes
@pytest.mark.parametrize("ros_type", sorted(rmw.TYPE_HASHES))
def test_the_pinned_type_hashes_are_those_rosbags_computes_for_jazzy(ros_type):
    from rosbags.typesys import Stores, get_typestore

    assert rmw.TYPE_HASHES[ros_type] == get_typestore(Stores.ROS2_JAZZY).hash_rihs01(ros_type)


def test_the_string_hash_is_the_one_the_design_document_prints():
    assert rmw.type_hash("std_msgs/msg/String") == STRING_HASH


# ---------------------------------------------------------------- the attachment
def test_the_attachment_is_the_design_documents_33_bytes():
    gid = bytes(range(16))
    data = rmw.Attachment(7, 1_700_000_000_123_456_789, gid).encode()
    assert data == (struct.pack("<q", 7) + struct.pack("<q", 1_700_000_000_123_456_789) + b"\x10" + gid)


def test_the_attachment_is_zenohs_own_serialisation_of_two_int64_and_16_bytes():
    gid = bytes(range(100, 116))
    ours = rmw.Attachment(-3, 42, gid).encode()
    assert ours == zenoh.ext.z_serialize((zenoh.ext.Int64(-3), zenoh.ext.Int64(42), gid)).to_bytes()
    seq, stamp, decoded_gid = zenoh.ext.z_deserialize(tuple[zenoh.ext.Int64, zenoh.ext.Int64, bytes],
                                                      zenoh.ZBytes(ours))
    assert (seq, stamp, decoded_gid) == (-3, 42, gid)


def test_an_attachment_decodes_to_what_was_encoded():
    a = rmw.Attachment(2**40, 5, b"\xff" * 16)
    assert rmw.Attachment.decode(a.encode()) == a


@pytest.mark.parametrize("data", [b"", b"\x00" * 32, b"\x00" * 34, b"\x00" * 16 + b"\x0f" + b"\x00" * 16, None,
                                  "x" * 33])
def test_anything_but_an_rmw_zenoh_attachment_is_a_bad_attachment(data):
    with pytest.raises(BadAttachment):
        rmw.Attachment.decode(data)


def test_a_gid_is_xxh3_128_low_half_first_little_endian():
    """XXH3-128 of the empty input is 0x99aa06d3014798d8_6001c324468d497f (xxHash's reference value): rmw_zenoh
    copies its low 64 bits, then its high 64 bits, in the host's (little-endian) order."""
    assert rmw.gid_of("") == bytes.fromhex("7f498d4624c30160" "d8984701d306aa99")


def test_an_entitys_gid_is_16_bytes_and_its_own():
    a = rmw.gid_of("@ros2_lv/0/ab/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/x/::,10:,:,:,,")
    b = rmw.gid_of("@ros2_lv/0/ab/0/2/MP/%/%/n/%t/std_msgs::msg::dds_::String_/x/::,10:,:,:,,")
    assert len(a) == len(b) == 16 and a != b


@given(st.binary(max_size=64))
def test_any_bytes_are_an_attachment_or_a_bad_attachment(data):
    try:
        a = rmw.Attachment.decode(data)
    except BadAttachment:
        return
    assert len(data) == 33 and a.encode() == data
