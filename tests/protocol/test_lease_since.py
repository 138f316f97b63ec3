"""Wire 1.2: `RobotState.lease_since`, when the holder was granted control (protocol/README.md §2.2)."""
import msgpack

from sharedctl.protocol.msgpack_codec import decode_message, encode_message, to_map

from .protocol_samples import state as robot_state


def test_lease_since_round_trips():
    assert decode_message(encode_message(robot_state(lease_since=1234.5))).lease_since == 1234.5


def test_a_1_1_payload_without_the_field_decodes_to_none():
    body = to_map(robot_state(lease_since=99.0))
    body["version"] = [1, 1]
    del body["lease_since"]
    assert decode_message(msgpack.packb(body, use_bin_type=True)).lease_since is None


def test_the_writer_speaks_1_2():
    assert to_map(robot_state())["version"] == [1, 2]
