"""Wire 1.1: `LinkHealth.rejected_messages`, a field added by a minor version (protocol/README.md §2.2)."""
import msgpack
import pytest

from sharedctl.protocol import messages as m
from sharedctl.protocol.errors import MissingField
from sharedctl.protocol.msgpack_codec import decode_message, encode_message, to_map

from .protocol_samples import state as robot_state


def test_rejected_messages_round_trips():
    state = robot_state(link=m.LinkHealth(1.0, 0.0, 2.0, 3.0, rejected_messages=17))
    assert decode_message(encode_message(state)).link.rejected_messages == 17


def test_a_1_0_payload_without_the_field_decodes_to_zero():
    body = to_map(robot_state())
    body["version"] = [1, 0]
    del body["link"]["rejected_messages"]
    decoded = decode_message(msgpack.packb(body, use_bin_type=True))
    assert decoded.link.rejected_messages == 0


def test_fields_without_a_default_are_still_required():
    body = to_map(robot_state())
    del body["link"]["staleness_ms"]
    with pytest.raises(MissingField):
        decode_message(msgpack.packb(body, use_bin_type=True))


def test_the_writer_speaks_1_1_or_later():
    assert to_map(robot_state())["version"] >= [1, 1]
