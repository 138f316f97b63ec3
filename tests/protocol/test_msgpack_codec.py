"""Specification of the MessagePack payloads carried over Zenoh."""
from __future__ import annotations

import math
import struct

import msgpack
import pytest
from hypothesis import given

from protocol_samples import command, heartbeat, state
from protocol_strategies import dims_strategy, messages_of
from sharedctl.protocol import messages as m
from sharedctl.protocol.errors import (
    MalformedPayload,
    MissingField,
    NonFiniteValue,
    OversizedPayload,
    UnexpectedKind,
    UnknownKind,
    UnsupportedVersion,
    WrongLength,
    WrongType,
)
from sharedctl.protocol.msgpack_codec import MAX_PAYLOAD_BYTES, decode_message, encode_message, to_map
from sharedctl.protocol.wire_types import Dims


def packed(body: dict) -> bytes:
    return msgpack.packb(body, use_bin_type=True)


def body_of(message, **changes) -> dict:
    body = to_map(message)
    body.update(changes)
    return body


def without(message, key: str) -> bytes:
    body = to_map(message)
    del body[key]
    return packed(body)


# --- round trips -----------------------------------------------------------------------------------

@pytest.mark.parametrize("cls", m.MESSAGE_TYPES, ids=lambda c: c.__name__)
def test_every_message_type_round_trips(cls):
    @given(messages_of(cls))
    def check(message):
        assert decode_message(encode_message(message)) == message

    check()


@pytest.mark.parametrize("cls", [m.OperatorCommand, m.RobotState, m.GroundTruth], ids=lambda c: c.__name__)
def test_messages_of_any_valid_dimensions_round_trip_with_those_dims(cls):
    @given(dims_strategy.flatmap(lambda d: messages_of(cls, d).map(lambda msg: (d, msg))))
    def check(dims_and_message):
        dims, message = dims_and_message
        assert decode_message(encode_message(message, dims), dims) == message

    check()


def test_payload_is_a_map_tagged_with_type_and_version_1_2():
    body = msgpack.unpackb(encode_message(heartbeat()))
    assert (body["type"], body["version"]) == ("heartbeat", [1, 2])


def test_enums_travel_as_their_string_values():
    assert msgpack.unpackb(encode_message(state()))["authority"] == "shared"


def test_link_health_travels_as_a_nested_map():
    assert msgpack.unpackb(encode_message(state()))["link"]["loss_fraction"] == 0.01


def test_expect_returns_the_message_of_that_type():
    assert decode_message(encode_message(heartbeat()), expect=m.Heartbeat) == heartbeat()


def test_expect_of_another_type_is_unexpected_kind():
    with pytest.raises(UnexpectedKind):
        decode_message(encode_message(heartbeat()), expect=m.RobotState)


def test_integers_are_accepted_in_float_fields():
    assert decode_message(packed(body_of(heartbeat(), time=3))).time == 3.0


def test_single_precision_floats_from_a_peer_are_accepted():
    payload = msgpack.packb(to_map(heartbeat()), use_single_float=True)
    assert decode_message(payload).time == 12.5


# --- versioning ------------------------------------------------------------------------------------------

def test_extra_unknown_field_on_the_same_version_is_ignored():
    assert decode_message(packed(body_of(heartbeat(), mood="fine"))) == heartbeat()


def test_newer_minor_with_extra_fields_is_accepted():
    payload = packed(body_of(heartbeat(), version=[1, 7], load=0.3, tags=["a", "b"]))
    assert decode_message(payload) == heartbeat()


def test_different_major_is_unsupported_version():
    with pytest.raises(UnsupportedVersion):
        decode_message(packed(body_of(heartbeat(), version=[2, 0])))


def test_major_zero_is_unsupported_version():
    with pytest.raises(UnsupportedVersion):
        decode_message(packed(body_of(heartbeat(), version=[0, 9])))


def test_unknown_major_is_refused_before_the_fields_are_read():
    with pytest.raises(UnsupportedVersion):
        decode_message(packed({"version": [3, 0], "type": "teleport"}))


def test_missing_version_is_missing_field():
    with pytest.raises(MissingField):
        decode_message(without(heartbeat(), "version"))


def test_version_as_string_is_wrong_type():
    with pytest.raises(WrongType):
        decode_message(packed(body_of(heartbeat(), version="1.0")))


def test_version_with_negative_minor_is_wrong_type():
    with pytest.raises(WrongType):
        decode_message(packed(body_of(heartbeat(), version=[1, -1])))


# --- kinds and missing fields -------------------------------------------------------------------------------

def test_unknown_type_is_unknown_kind():
    with pytest.raises(UnknownKind):
        decode_message(packed(body_of(heartbeat(), type="teleport")))


def test_missing_type_is_missing_field():
    with pytest.raises(MissingField):
        decode_message(without(heartbeat(), "type"))


def test_type_as_integer_is_wrong_type():
    with pytest.raises(WrongType):
        decode_message(packed(body_of(heartbeat(), type=4)))


@pytest.mark.parametrize("field", [name for name, _, _ in m.RobotState.WIRE_FIELDS
                                   if name not in m.RobotState.WIRE_DEFAULTS])
def test_robot_state_without_a_required_field_is_missing_field(field):
    with pytest.raises(MissingField):
        decode_message(without(state(), field))


@pytest.mark.parametrize("field", [name for name, _, _ in m.OperatorCommand.WIRE_FIELDS])
def test_operator_command_without_a_required_field_is_missing_field(field):
    with pytest.raises(MissingField):
        decode_message(without(command(), field))


def test_link_health_without_loss_fraction_is_missing_field():
    body = to_map(state())
    del body["link"]["loss_fraction"]
    with pytest.raises(MissingField):
        decode_message(packed(body))


def test_link_health_with_an_extra_field_is_accepted():
    body = to_map(state())
    body["link"]["jitter_ms"] = 3.0
    assert decode_message(packed(body)) == state()


# --- array lengths -----------------------------------------------------------------------------------------

def test_pose_of_two_entries_for_a_three_dof_receiver_is_wrong_length():
    with pytest.raises(WrongLength):
        decode_message(encode_message(m.GroundTruth(seq=0, time=0.0, q=(1.0, 2.0), qd=(0.0, 0.0))))


def test_dof_arrays_of_different_lengths_are_wrong_length():
    with pytest.raises(WrongLength):
        decode_message(packed(body_of(state(), u_h=[1.0, 2.0, 3.0, 4.0])))


def test_theta_of_four_entries_for_n_theta_3_is_wrong_length():
    with pytest.raises(WrongLength):
        decode_message(packed(body_of(state(), theta_hat=[1.0, 2.0, 3.0, 4.0])))


def test_two_wheel_torques_for_three_wheels_is_wrong_length():
    with pytest.raises(WrongLength):
        decode_message(packed(body_of(state(), wheel_torques=[1.0, 2.0])))


def test_encoding_for_other_dims_is_wrong_length():
    with pytest.raises(WrongLength):
        encode_message(state(), Dims(dof=4, n_theta=3, n_wheels=3))


def test_dims_none_accepts_any_valid_length():
    message = m.GroundTruth(seq=0, time=0.0, q=(1.0, 2.0), qd=(0.0, 0.0))
    assert decode_message(encode_message(message), None) == message


# --- wrong types -------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("field, value", [
    ("time", "12.5"), ("time", True), ("time", None), ("seq", 1.0), ("seq", "7"), ("role", 5),
    ("role", b"controller"), ("id", ["ctl"]),
])
def test_heartbeat_field_of_the_wrong_type_is_wrong_type(field, value):
    with pytest.raises(WrongType):
        decode_message(packed(body_of(heartbeat(), **{field: value})))


@pytest.mark.parametrize("field, value", [
    ("deadman", 1), ("estop", "false"), ("q_d", {"x": 1.0}), ("q_d", [1.0, "2", 3.0]), ("joystick", 0.5),
    ("control_request", 1),
])
def test_operator_command_field_of_the_wrong_type_is_wrong_type(field, value):
    with pytest.raises(WrongType):
        decode_message(packed(body_of(command(), **{field: value})))


def test_link_as_array_is_wrong_type():
    with pytest.raises(WrongType):
        decode_message(packed(body_of(state(), link=[1.0, 0.0, 1.0, 1.0])))


def test_top_level_array_is_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(packed([1, 0, "heartbeat"]))


def test_payload_given_as_str_is_wrong_type():
    with pytest.raises(WrongType):
        decode_message("heartbeat")


def test_encoding_a_non_message_is_wrong_type():
    with pytest.raises(WrongType):
        encode_message({"type": "heartbeat"})


# --- non-finite values ----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_decoding_a_non_finite_float_is_refused(bad):
    with pytest.raises(NonFiniteValue):
        decode_message(packed(body_of(heartbeat(), time=bad)))


def test_decoding_nan_inside_an_array_is_refused():
    with pytest.raises(NonFiniteValue):
        decode_message(packed(body_of(command(), q_d=[0.0, math.nan, 0.0])))


def test_decoding_a_single_precision_nan_is_refused():
    body = msgpack.packb(body_of(heartbeat(), time=0.0))
    nan32 = body.replace(b"\xcb" + struct.pack(">d", 0.0), b"\xca" + struct.pack(">f", math.nan))
    with pytest.raises(NonFiniteValue):
        decode_message(nan32)


# --- malformed and oversized payloads -------------------------------------------------------------------------------

def test_empty_payload_is_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(b"")


def test_truncated_payload_is_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(encode_message(heartbeat())[:-1])


def test_trailing_bytes_are_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(encode_message(heartbeat()) + b"\xc0")


def test_duplicate_key_is_malformed():
    body = encode_message(heartbeat())
    duplicated = b"\x87" + body[1:] + msgpack.packb("seq") + msgpack.packb(8)  # 6 keys + one repeated
    with pytest.raises(MalformedPayload):
        decode_message(duplicated)


def test_integer_map_key_is_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(msgpack.packb({1: 2}))


def test_binary_map_key_is_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(msgpack.packb({b"type": "heartbeat"}, use_bin_type=True))


def test_extension_type_is_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(packed(body_of(heartbeat(), extra=msgpack.ExtType(5, b"\x00"))))


def test_empty_extension_type_is_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(packed(body_of(heartbeat(), extra=msgpack.ExtType(5, b""))))


def test_timestamp_extension_is_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(packed(body_of(heartbeat(), time=msgpack.Timestamp(1, 0))))


def test_map_header_claiming_four_billion_entries_is_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(b"\xdf\xff\xff\xff\xff" + b"\xa1a\x01" * 4)


def test_string_header_claiming_four_gigabytes_is_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(b"\x81\xa1a\xdb\xff\xff\xff\xff")


def test_deeply_nested_arrays_are_malformed():
    with pytest.raises(MalformedPayload):
        decode_message(b"\x91" * 3000 + b"\xc0")


def test_payload_above_the_global_bound_is_oversized():
    with pytest.raises(OversizedPayload):
        decode_message(b"\x80" + bytes(MAX_PAYLOAD_BYTES))


def test_heartbeat_padded_beyond_its_bound_is_oversized():
    payload = packed(body_of(heartbeat(), padding="x" * 600))
    assert len(payload) <= MAX_PAYLOAD_BYTES  # below the global bound, above the heartbeat's
    with pytest.raises(OversizedPayload):
        decode_message(payload)


def _largest(cls):
    n, token, text = 8, "a" * 64, "\U0001F600" * 256
    v = tuple([-1.2345678901234567e308] * n)
    if cls is m.OperatorCommand:
        return cls(operator_id=token, session_id=token, seq=2**64 - 1, send_time=1e308, joystick=(-0.123456789,) * n,
                   q_d=v, qd_d=v, qdd_d=v, deadman=True, estop=True, control_request="release")
    if cls is m.RobotState:
        return state(seq=2**64 - 1, time=1e308, q=v, qd_hat=v, q_ref=v, group_classes=["hysteresis"] * 16,
                     active_group=15, u_h=v, u_f=v, u_s=v, wheel_torques=v, theta_hat=(-1e308,) * 16,
                     region_margins=(-1e308,) * 32, lease_holder=token, authority="machine",
                     min_margin=-1e308, k_s=0.1234567, k_h=0.1234567, k_f=0.1234567,
                     link=m.LinkHealth(1e308, 0.123456789, 1e308, 1e308, 2**64 - 1))
    if cls is m.Event:
        return cls(seq=2**64 - 1, time=1e308, kind="authority_change", severity="critical", source=token, text=text)
    if cls is m.Heartbeat:
        return cls(role=token, id=token, seq=2**64 - 1, time=1e308)
    if cls is m.LeaseRequest:
        return cls(operator_id=token, session_id=token, seq=2**64 - 1, time=1e308, action="release")
    if cls is m.LeaseReply:
        return cls(request_seq=2**64 - 1, time=1e308, granted=False, holder=token, reason=text)
    return cls(seq=2**64 - 1, time=1e308, q=v, qd=v)


@pytest.mark.parametrize("cls", m.MESSAGE_TYPES, ids=lambda c: c.__name__)
def test_largest_valid_message_fits_within_half_its_bound(cls):
    assert len(encode_message(_largest(cls))) <= cls.MAX_BYTES // 2
