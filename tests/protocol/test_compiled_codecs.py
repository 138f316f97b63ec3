"""The compiled codec of every frame kind (protocol/cancodec.py, `cansimple.CODECS`) against independent
oracles: ODrive's published byte layout written out by hand, and cantools encoding and decoding the
project's DBC, with the validity rules of protocol/README.md §1.2 written out here."""
from __future__ import annotations

import math
import struct

import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.cancodec import FrameCodec
from sharedctl.protocol.canspec import FrameSpec, SignalSpec
from sharedctl.protocol.dbc import DBC_PATH
from sharedctl.protocol.errors import BadLength, NonFiniteValue, OutOfRange
from sharedctl.protocol.odrive_enums import CommandId, ODriveError

# ODrive's published layout (odrive-cansimple-0.6.10.dbc) as little-endian struct formats, by hand
PUBLISHED_LAYOUT = {
    "Heartbeat": "<IBBB1x",                 # u32 error, u8 state, u8 result, bit 48 in byte 6, byte 7 unused
    "Estop": "<",
    "Get_Error": "<II",
    "Set_Axis_State": "<I4x",
    "Get_Encoder_Estimates": "<ff",
    "Set_Controller_Mode": "<II",
    "Set_Input_Vel": "<ff",
    "Set_Input_Torque": "<f4x",
    "Set_Limits": "<ff",
    "Get_Iq": "<ff",
    "Get_Bus_Voltage_Current": "<ff",
    "Clear_Errors": "<B",
    "Get_Torques": "<ff",
}
# validity of the integer signals (protocol/README.md §1.2): ODriveError bit fields take any combination,
# these take 0 or 1, every other one a value of its DBC value table; these floats must be ≥ 0
BIT_FIELDS = {"Axis_Error", "Active_Errors", "Disarm_Reason"}
ZERO_OR_ONE = {"Identify", "Trajectory_Done_Flag"}
NON_NEGATIVE = {"Velocity_Limit", "Current_Limit"}

kinds = sorted(cs.FRAME_SPECS, key=lambda cls: cs.FRAME_SPECS[cls].cmd)


@pytest.fixture(scope="module")
def db():
    return cantools.database.load_file(str(DBC_PATH))


def _dbc_message(db, cls):
    return db.get_message_by_name(f"Axis0_{cs.FRAME_SPECS[cls].name}")


def _expected(dbc_message, decoded: dict) -> tuple[type | None, list]:
    """(the error the codec must raise or None, the signal values in table order), by the rules above."""
    values = []
    for signal in sorted(dbc_message.signals, key=lambda s: s.start):
        value = decoded[signal.name]
        if signal.is_float:
            if not math.isfinite(value):
                return NonFiniteValue, values
            if signal.name in NON_NEGATIVE and value < 0:
                return OutOfRange, values
        elif signal.name in ZERO_OR_ONE:
            if value not in (0, 1):
                return OutOfRange, values
        elif signal.name not in BIT_FIELDS and value not in signal.choices:
            return OutOfRange, values
        values.append(value)
    return None, values


def _bytes_of(n: int) -> st.SearchStrategy:
    """n bytes: uniformly random, or from an alphabet that makes NaN, ±inf, small and huge values often."""
    special = st.lists(st.sampled_from([b"\x00", b"\x01", b"\x7f", b"\x80", b"\xc0", b"\xff"]), min_size=n, max_size=n)
    return st.binary(min_size=n, max_size=n) | special.map(b"".join)


@pytest.mark.parametrize("cls", kinds, ids=lambda c: c.__name__)
def test_every_kind_compiles_to_odrives_published_byte_layout(cls):
    codec = cs.CODECS[cls]
    assert (codec.layout.format, codec.layout.size) == (PUBLISHED_LAYOUT[codec.spec.name], codec.spec.dlc)


@pytest.mark.parametrize("cls", kinds, ids=lambda c: c.__name__)
def test_unpacking_any_bytes_agrees_with_cantools_and_the_validity_rules(db, cls):
    codec, dbc_message = cs.CODECS[cls], _dbc_message(db, cls)

    @given(_bytes_of(codec.spec.dlc))
    def check(data):
        error, values = _expected(dbc_message, dbc_message.decode(data, decode_choices=False, scaling=False))
        if error is not None:
            with pytest.raises(error):
                codec.unpack(data)
        else:
            assert [float(v) if isinstance(v, float) else int(v) for v in codec.unpack(data)] == values

    check()


@pytest.mark.parametrize("cls", kinds, ids=lambda c: c.__name__)
def test_packing_valid_values_gives_the_bytes_cantools_encodes(db, cls):
    codec, dbc_message = cs.CODECS[cls], _dbc_message(db, cls)
    signals = sorted(dbc_message.signals, key=lambda s: s.start)

    def valid(signal):
        if signal.is_float:
            return st.floats(min_value=0.0 if signal.name in NON_NEGATIVE else None, width=32,
                             allow_nan=False, allow_infinity=False)
        if signal.name in ZERO_OR_ONE:
            return st.sampled_from([False, True])
        if signal.name in BIT_FIELDS:
            return st.integers(0, 2**32 - 1)
        return st.sampled_from(sorted(signal.choices))

    @given(st.tuples(*(valid(s) for s in signals)))
    def check(values):
        assert codec.pack(values) == dbc_message.encode({s.name: int(v) if isinstance(v, bool) else v
                                                         for s, v in zip(signals, values)}, scaling=False)

    check()


@pytest.mark.parametrize("cls", [c for c in kinds if cs.FRAME_SPECS[c].dlc > 0], ids=lambda c: c.__name__)
def test_data_of_another_length_than_the_dlc_is_bad_length(cls):
    codec = cs.CODECS[cls]
    with pytest.raises(BadLength):
        codec.unpack(bytes(codec.spec.dlc - 1))
    with pytest.raises(BadLength):
        codec.unpack(bytes(codec.spec.dlc + 1))


def test_unused_bits_of_the_heartbeat_are_ignored_on_decode():
    data = struct.pack("<IBBB", 0, 8, 0, 0b1111_1111) + b"\xff"       # bit 48 set, bits 49..63 set too
    assert cs.CODECS[cs.Heartbeat].unpack(data)[-1] is True


def test_an_enum_member_beyond_its_signals_bits_is_out_of_range():
    with pytest.raises(OutOfRange):
        cs.Heartbeat(0, ODriveError(1 << 40))


def test_a_table_that_does_not_start_on_byte_boundaries_is_refused_when_compiled():
    spec = FrameSpec(CommandId.SET_AXIS_STATE, "Odd", 8, "host",
                     (SignalSpec("Half", "half", 4, 4, "bool"),), "a signal inside a byte")
    with pytest.raises(ValueError, match="cannot be compiled"):
        FrameCodec(spec)


def test_a_table_that_overruns_its_dlc_is_refused_when_compiled():
    spec = FrameSpec(CommandId.SET_AXIS_STATE, "Long", 4, "host",
                     (SignalSpec("Wide", "wide", 16, 32, "flag", "", CommandId),), "a signal past the DLC")
    with pytest.raises(ValueError, match="DLC"):
        FrameCodec(spec)
