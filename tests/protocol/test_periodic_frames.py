"""The per-period entry points of the CANSimple codec (`torque_frame`, `periodic_kind`, `encoder_estimates`):
the bytes and values cantools gives for the project's DBC and bytes computed by hand, and exactly the
acceptance of the general decoder, frame for frame, on fuzzed frames."""
from __future__ import annotations

import math
import struct

import cantools
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.dbc import DBC_PATH
from sharedctl.protocol.errors import BadNodeId, NonFiniteValue, OutOfRange, ProtocolError, WrongType

DB = cantools.database.load_file(str(DBC_PATH))
TORQUE = DB.get_message_by_name("Axis0_Set_Input_Torque")       # the layout of every node's frame
ENCODER = DB.get_message_by_name("Axis0_Get_Encoder_Estimates")
NAN, INF = struct.pack("<f", math.nan), struct.pack("<f", math.inf)


# --- torque_frame --------------------------------------------------------------------------------

def test_a_torque_frame_is_the_id_and_bytes_computed_by_hand():
    # node 1 << 5 | 0x0E = 0x2E; 1.5 = 0x3FC00000 little-endian; bytes 4..7 zero
    assert cs.torque_frame(1, 1.5) == (0x02E, bytes.fromhex("0000c03f00000000"))


@given(st.sampled_from([0, 1, 2]), st.floats(-3.4e38, 3.4e38))
def test_cantools_reads_the_torque_of_a_torque_frame_and_its_padding_is_zero(node, torque):
    arb, data = cs.torque_frame(node, torque)
    message = DB.get_message_by_frame_id(arb)
    assert message.name == f"Axis{node}_Set_Input_Torque"
    assert message.decode(data) == {"Input_Torque": struct.unpack("<f", struct.pack("<f", torque))[0]}
    assert data[4:] == bytes(4)


@given(st.integers(0, 63), st.floats(allow_nan=True, allow_infinity=True) | st.integers(-2**200, 2**200))
@example(0, 3.4028235677973366e38)      # rounds to the largest float32
@example(0, 3.4028235677973367e38)      # rounds beyond it
def test_a_torque_frame_is_the_general_encoders_frame_or_its_error(node, torque):
    try:
        frame = cs.encode(cs.SetInputTorque(node, torque))
    except ProtocolError as exc:
        with pytest.raises(type(exc)):
            cs.torque_frame(node, torque)
    else:
        assert cs.torque_frame(node, torque) == (frame.arbitration_id, frame.data)


@pytest.mark.parametrize("bad, error", [(math.nan, NonFiniteValue), (math.inf, NonFiniteValue),
                                        (-math.inf, NonFiniteValue), (1e39, OutOfRange), ("1.0", WrongType),
                                        (True, WrongType)])
def test_a_torque_the_codec_refuses_raises_the_codecs_error(bad, error):
    with pytest.raises(error):
        cs.torque_frame(0, bad)
    with pytest.raises(error):
        cs.SetInputTorque(0, bad)


@pytest.mark.parametrize("node", [64, -1, True, 1.0])
def test_a_torque_frame_to_a_node_outside_0_to_63_is_bad_node_id(node):
    with pytest.raises(BadNodeId):
        cs.torque_frame(node, 0.0)


# --- periodic_kind and encoder_estimates ----------------------------------------------------------

def _by_hand(arbitration_id, dlc, data, is_remote, is_extended_id, nodes) -> type | None:
    """The oracle: protocol/README.md §1 with cantools reading the signals."""
    if is_remote or is_extended_id or not 0 <= arbitration_id <= 0x7FF or dlc != 8 or len(data) != 8:
        return None
    if nodes is not None and arbitration_id >> 5 not in nodes:
        return None
    cmd = arbitration_id & 0x1F
    message = {0x09: ENCODER, 0x0E: TORQUE}.get(cmd)
    if message is None or not all(math.isfinite(v) for v in message.decode(data).values()):
        return None
    return cs.GetEncoderEstimates if cmd == 0x09 else cs.SetInputTorque


floats32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
payloads = (st.binary(min_size=0, max_size=9)
            | st.tuples(floats32 | st.sampled_from([math.nan, math.inf, -math.inf, -0.0]),
                        floats32 | st.sampled_from([math.nan, -math.inf])).map(lambda v: struct.pack("<ff", *v)))


@st.composite
def fuzzed_frames(draw):
    """Frames around the two kinds: their ids on nodes in and out of `nodes`, other commands and ids
    beyond 11 bits, wrong DLCs and lengths, RTR and extended flags, NaN/inf and random payloads."""
    node = draw(st.sampled_from([0, 1, 2, 3, 63, 64, 127, -1]))       # the last three: ids beyond 11 bits
    cmd = draw(st.sampled_from([0x09, 0x0E, 0x01, 0x0D, 0x1C, 0x1F]))
    arbitration_id = draw(st.just(node << 5 | cmd) | st.integers(-1, 0x900))
    remote = draw(st.integers(0, 9)) == 0
    data = draw(st.just(b"") | payloads) if remote else draw(payloads)       # a remote frame with data: refused
    dlc = draw(st.just(len(data)) | st.integers(0, 9))
    extended = draw(st.integers(0, 9)) == 0
    nodes = draw(st.sampled_from([None, (0, 1, 2), frozenset({1}), ()]))
    return arbitration_id, dlc, data, remote, extended, nodes


def _general(arbitration_id, dlc, data, is_remote, is_extended_id, nodes):
    try:
        return cs.decode(arbitration_id, data, is_remote, dlc=dlc, is_extended_id=is_extended_id, nodes=nodes)
    except ProtocolError:
        return None


@settings(max_examples=3000)
@given(fuzzed_frames())
def test_periodic_kind_answers_what_the_spec_says_of_every_frame(frame):
    assert cs.periodic_kind(*frame) is _by_hand(*frame)


@settings(max_examples=3000)
@given(fuzzed_frames())
def test_the_per_period_path_and_the_general_decoder_agree_on_every_frame(frame):
    decoded = _general(*frame)
    kind = cs.periodic_kind(*frame)
    assert kind is (type(decoded) if type(decoded) in cs.PERIODIC_KINDS else None)
    if kind is cs.GetEncoderEstimates:
        assert cs.encoder_estimates(frame[2]) == (decoded.pos_estimate, decoded.vel_estimate)


@given(st.sampled_from([0, 1, 2]), floats32, floats32)
def test_encoder_estimates_are_the_values_cantools_decodes(node, pos, vel):
    message = DB.get_message_by_name(f"Axis{node}_Get_Encoder_Estimates")
    data = message.encode({"Pos_Estimate": pos, "Vel_Estimate": vel})
    assert cs.periodic_kind(message.frame_id, 8, data, nodes=(0, 1, 2)) is cs.GetEncoderEstimates
    assert cs.encoder_estimates(data) == (pos, vel)


def test_an_estimate_or_torque_with_a_nan_is_left_to_the_general_decoder():
    assert cs.periodic_kind(0x009, 8, NAN + bytes(4)) is None
    assert cs.periodic_kind(0x009, 8, bytes(4) + INF) is None
    assert cs.periodic_kind(0x00E, 8, NAN + bytes(4)) is None
    assert cs.periodic_kind(0x00E, 8, bytes(4) + NAN) is cs.SetInputTorque     # bytes 4..7 are padding


@pytest.mark.parametrize("fields", [
    (14.0, 8, bytes(8), False, False, None),            # id not an int
    (0x0E, True, bytes(8), False, False, None),          # DLC a bool
    (0x0E, 8.0, bytes(8), False, False, None),           # DLC a float
    (0x0E, 8, bytearray(8), False, False, None),         # data not bytes: decode judges it
    (0x0E, 8, "abcdefgh", False, False, None),
    (0x0E, 8, None, False, False, None),
    (0x0E, 8, bytes(8), 0, False, None),                 # flags not bools
    (0x0E, 8, bytes(8), False, None, None),
    ([0x0E], 8, bytes(8), False, False, None),
])
def test_odd_fields_are_left_to_the_general_decoder_and_never_raise(fields):
    assert cs.periodic_kind(*fields) is None
