"""Fuzzing: decoders only ever return valid typed values or raise ProtocolError.

Bulk: 100,000 seeded random and mutated inputs per decoder (protocol/fuzz.py).
Structure-aware: hypothesis mutations of valid messages and frames.
"""
from __future__ import annotations

import math

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol_strategies import any_message, can_messages, msgpack_values
from sharedctl.protocol import cansimple as cs
from sharedctl.protocol import fuzz
from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.keys import parse_key
from sharedctl.protocol.msgpack_codec import decode_message, encode_message, to_map

BULK = 100_000


@pytest.fixture(scope="module", params=fuzz.DECODERS)
def bulk_report(request):
    return fuzz.run_campaign(request.param, BULK, seed=2024)


def test_bulk_campaign_feeds_100k_inputs_per_decoder(bulk_report):
    assert bulk_report.inputs == BULK


def test_bulk_campaign_has_no_escapes(bulk_report):
    assert (bulk_report.escapes, bulk_report.examples) == (0, [])


def test_bulk_campaign_reaches_both_typed_errors_and_valid_values(bulk_report):
    share_accepted = bulk_report.accepted / bulk_report.inputs
    assert (bulk_report.typed_errors > 0, 0.01 < share_accepted < 0.9) == (True, True)


def test_campaign_counts_a_foreign_exception_as_an_escape():
    def broken(_):
        raise KeyError("not a protocol error")

    report = fuzz.fuzz_inputs("x", iter(range(3)), broken, lambda _: True, fuzz.FuzzReport("x"))
    assert report.escapes == 3


def test_campaign_counts_an_invalid_accepted_value_as_an_escape():
    report = fuzz.fuzz_inputs("x", iter([math.nan]), lambda v: v, lambda v: not math.isnan(v), fuzz.FuzzReport("x"))
    assert report.escapes == 1


def test_campaign_is_reproducible_from_its_seed():
    first, second = fuzz.run_campaign("message", 500, seed=7), fuzz.run_campaign("message", 500, seed=7)
    assert (first.accepted, first.errors) == (second.accepted, second.errors)


def test_unknown_decoder_name_is_refused():
    with pytest.raises(ValueError):
        fuzz.run_campaign("zenoh", 1)


# --- structure-aware (hypothesis) -------------------------------------------------------------------------

def _decodes_or_typed_error(payload: bytes) -> bool:
    try:
        decoded = decode_message(payload)
    except ProtocolError:
        return True
    return fuzz.is_valid_message_output(decoded)


@settings(suppress_health_check=[HealthCheck.too_slow])
@given(any_message, st.data())
def test_message_with_a_field_replaced_by_any_value_decodes_or_raises_typed_error(message, data):
    body = to_map(message)
    key = data.draw(st.sampled_from(sorted(body)))
    body[key] = data.draw(msgpack_values)
    assert _decodes_or_typed_error(msgpack.packb(body, use_bin_type=True))


@given(any_message, st.data())
def test_message_with_fields_removed_or_added_decodes_or_raises_typed_error(message, data):
    body = to_map(message)
    for key in data.draw(st.lists(st.sampled_from(sorted(body)), max_size=3)):
        body.pop(key, None)
    body.update(data.draw(st.dictionaries(st.text(max_size=12), msgpack_values, max_size=3)))
    assert _decodes_or_typed_error(msgpack.packb(body, use_bin_type=True))


@given(any_message, st.data())
def test_message_with_bytes_mutated_decodes_or_raises_typed_error(message, data):
    payload = bytearray(encode_message(message))
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(payload) - 1))
        payload[i] = data.draw(st.integers(0, 255))
    assert _decodes_or_typed_error(bytes(payload))


@given(msgpack_values)
def test_any_msgpack_value_decodes_or_raises_typed_error(value):
    assert _decodes_or_typed_error(msgpack.packb(value, use_bin_type=True))


@given(st.binary(max_size=512))
def test_any_bytes_decode_or_raise_typed_error(payload):
    assert _decodes_or_typed_error(payload)


def _frame_decodes_or_typed_error(arb, data, is_remote, dlc) -> bool:
    try:
        decoded = cs.decode(arb, data, is_remote, dlc=dlc)
    except ProtocolError:
        return True
    return fuzz.is_valid_can_output(decoded)


@given(st.integers(0, 0x7FF), st.binary(max_size=8), st.booleans(), st.integers(0, 8))
def test_any_standard_frame_decodes_or_raises_typed_error(arb, data, is_remote, dlc):
    payload = b"" if is_remote else data
    assert _frame_decodes_or_typed_error(arb, payload, is_remote, dlc if is_remote else None)


@given(can_messages, st.data())
def test_valid_frame_with_one_byte_changed_decodes_or_raises_typed_error(message, data):
    frame = cs.encode(message)
    payload = bytearray(frame.data)
    if payload:
        payload[data.draw(st.integers(0, len(payload) - 1))] = data.draw(st.integers(0, 255))
    assert _frame_decodes_or_typed_error(frame.arbitration_id, bytes(payload), frame.is_remote,
                                         frame.dlc if frame.is_remote else None)


@given(st.text(max_size=120))
def test_any_text_parses_as_a_key_or_raises_typed_error(text):
    try:
        parsed = parse_key(text)
    except ProtocolError:
        parsed = None
    assert parsed is None or fuzz.is_valid_key_output(parsed)
