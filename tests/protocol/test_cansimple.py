"""Specification of the ODrive CANSimple (0.6) codec."""
from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given

from protocol_strategies import can_messages, data_frame_classes, frames_of
from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.canframe import CanFrame, arbitration_id, split_arbitration_id
from sharedctl.protocol.errors import (
    BadArbitrationId,
    BadLength,
    BadNodeId,
    NonFiniteValue,
    OutOfRange,
    UnexpectedRemote,
    UnknownCommand,
    WrongType,
)
from sharedctl.protocol.odrive_enums import (
    AxisState,
    CommandId,
    ControlMode,
    InputMode,
    ODriveError,
    ProcedureResult,
)

NAN_BITS = struct.pack("<f", math.nan)
INF_BITS = struct.pack("<f", math.inf)


# --- arbitration ids ---------------------------------------------------------------------------

def test_arbitration_id_is_node_shifted_by_five_or_command():
    assert arbitration_id(0x01, 0x0C) == 0x2C  # the example of ODrive's CAN protocol page


def test_split_arbitration_id_returns_node_and_command():
    assert split_arbitration_id(0x2C) == (0x01, 0x0C)


def test_highest_node_id_63_is_accepted():
    assert cs.encode(cs.Estop(63)).arbitration_id == 63 << 5 | 0x02


def test_node_id_64_is_refused():
    with pytest.raises(BadNodeId):
        cs.Estop(64)


def test_negative_node_id_is_refused():
    with pytest.raises(BadNodeId):
        cs.Estop(-1)


def test_decode_refuses_node_outside_configured_nodes():
    frame = cs.encode(cs.Estop(5))
    with pytest.raises(BadNodeId):
        cs.decode_frame(frame, nodes=(0, 1, 2))


def test_decode_accepts_node_inside_configured_nodes():
    frame = cs.encode(cs.Estop(2))
    assert cs.decode_frame(frame, nodes=(0, 1, 2)) == cs.Estop(2)


def test_extended_id_frame_is_refused():
    with pytest.raises(BadArbitrationId):
        cs.decode(0x009, bytes(8), is_extended_id=True)


def test_arbitration_id_beyond_11_bits_is_refused():
    with pytest.raises(BadArbitrationId):
        cs.decode(0x800, bytes(8))


# --- byte layout (matches ODrive's DBC and its Python examples) ----------------------------------

def test_heartbeat_layout_is_error_u32_state_u8_result_u8_done_bit():
    frame = cs.encode(cs.Heartbeat(0, ODriveError.ESTOP_REQUESTED, AxisState.CLOSED_LOOP_CONTROL,
                                   ProcedureResult.BUSY, True))
    assert frame.data == struct.pack("<IBBBx", 0x2000000, 8, 1, 1)


def test_set_input_vel_layout_is_two_little_endian_float32():
    frame = cs.encode(cs.SetInputVel(0, 1.5, -0.25))
    assert (frame.arbitration_id, frame.data) == (0x00D, struct.pack("<ff", 1.5, -0.25))


def test_set_axis_state_layout_is_u32_padded_to_dlc_8():
    frame = cs.encode(cs.SetAxisState(1, AxisState.CLOSED_LOOP_CONTROL))
    assert (frame.arbitration_id, frame.data) == (0x027, struct.pack("<I4x", 8))


def test_set_controller_mode_layout_is_control_mode_then_input_mode():
    frame = cs.encode(cs.SetControllerMode(0, ControlMode.TORQUE_CONTROL, InputMode.PASSTHROUGH))
    assert frame.data == struct.pack("<II", 1, 1)


def test_estop_is_an_empty_data_frame():
    frame = cs.encode(cs.Estop(2))
    assert (frame.arbitration_id, frame.data, frame.is_remote) == (0x042, b"", False)


def test_clear_errors_carries_one_identify_byte():
    assert cs.encode(cs.ClearErrors(0, identify=True)).data == b"\x01"


def test_encoder_estimates_decode_positions_in_turns():
    frame = CanFrame(0x029, struct.pack("<ff", 2.5, -1.0))
    assert cs.decode_frame(frame) == cs.GetEncoderEstimates(1, 2.5, -1.0)


def test_float_fields_are_rounded_to_float32_when_built():
    assert cs.SetInputTorque(0, 0.1).input_torque == struct.unpack("<f", struct.pack("<f", 0.1))[0]


def test_numpy_scalars_are_accepted_as_floats():
    import numpy as np

    assert cs.SetInputTorque(0, np.float32(0.5)).input_torque == 0.5


def test_unknown_error_bits_are_kept():
    frame = CanFrame(0x001, struct.pack("<IBBBx", 0x80000001, 1, 0, 0))
    assert int(cs.decode_frame(frame).axis_error) == 0x80000001


def test_heartbeat_reserved_bits_are_ignored_on_decode():
    frame = CanFrame(0x001, struct.pack("<IBBBB", 0, 1, 0, 0xFE, 0xFF))
    assert cs.decode_frame(frame) == cs.Heartbeat(0, ODriveError.NONE, AxisState.IDLE)


# --- round trips -----------------------------------------------------------------------------------

@pytest.mark.parametrize("cls", [*data_frame_classes, cs.PollRequest], ids=lambda c: c.__name__)
def test_every_frame_type_round_trips(cls):
    @given(frames_of(cls))
    def check(message):
        assert cs.decode_frame(cs.encode(message)) == message

    check()


@given(can_messages)
def test_decode_of_raw_fields_equals_decode_of_frame(message):
    frame = cs.encode(message)
    assert cs.decode(frame.arbitration_id, frame.data, frame.is_remote, dlc=frame.dlc) == message


# --- RTR polling -----------------------------------------------------------------------------------

def test_poll_is_a_remote_frame_with_the_get_id_and_dlc_8():
    frame = cs.poll(1, CommandId.GET_ENCODER_ESTIMATES)
    assert (frame.arbitration_id, frame.is_remote, frame.dlc, frame.data) == (0x029, True, 8, b"")


def test_remote_frame_with_dlc_0_decodes_as_poll_request():
    decoded = cs.decode(0x034, b"", is_remote=True, dlc=0)
    assert decoded == cs.PollRequest(1, CommandId.GET_IQ, dlc=0)


def test_remote_frame_with_dlc_8_decodes_as_poll_request():
    decoded = cs.decode(0x057, b"", is_remote=True, dlc=8)
    assert decoded == cs.PollRequest(2, CommandId.GET_BUS_VOLTAGE_CURRENT)


def test_remote_frame_with_other_dlc_is_bad_length():
    with pytest.raises(BadLength):
        cs.decode(0x034, b"", is_remote=True, dlc=4)


@pytest.mark.parametrize("cmd", [c for c in CommandId if c not in cs.POLLABLE_COMMANDS],
                         ids=lambda c: c.name)
def test_remote_frame_on_a_non_get_frame_is_unexpected_remote(cmd):
    with pytest.raises(UnexpectedRemote):
        cs.decode(arbitration_id(0, cmd), b"", is_remote=True, dlc=0)


def test_poll_request_for_a_command_frame_cannot_be_built():
    with pytest.raises(UnexpectedRemote):
        cs.PollRequest(0, CommandId.SET_INPUT_TORQUE)


def test_remote_frame_carrying_data_is_bad_length():
    with pytest.raises(BadLength):
        CanFrame(0x034, b"\x00", is_remote=True)


def test_pollable_commands_are_the_get_frames():
    assert {c.name for c in cs.POLLABLE_COMMANDS} == {
        "GET_ERROR", "GET_ENCODER_ESTIMATES", "GET_IQ", "GET_BUS_VOLTAGE_CURRENT", "GET_TORQUES"}


# --- wrong DLC ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("cls", [c for c in data_frame_classes if cs.FRAME_SPECS[c].dlc > 0],
                         ids=lambda c: c.__name__)
def test_data_frame_one_byte_short_is_bad_length(cls):
    spec = cs.FRAME_SPECS[cls]
    with pytest.raises(BadLength):
        cs.decode(arbitration_id(0, spec.cmd), bytes(spec.dlc - 1))


@pytest.mark.parametrize("cls", [c for c in data_frame_classes if cs.FRAME_SPECS[c].dlc < 8],
                         ids=lambda c: c.__name__)
def test_data_frame_one_byte_long_is_bad_length(cls):
    spec = cs.FRAME_SPECS[cls]
    with pytest.raises(BadLength):
        cs.decode(arbitration_id(0, spec.cmd), bytes(spec.dlc + 1))


def test_four_byte_set_axis_state_is_bad_length():
    with pytest.raises(BadLength):  # ODrive's own example sends 4 bytes; sharedctl is strict
        cs.decode(0x007, struct.pack("<I", 8))


def test_nine_data_bytes_are_bad_length():
    with pytest.raises(BadLength):
        CanFrame(0x009, bytes(9))


def test_dlc_disagreeing_with_data_is_bad_length():
    with pytest.raises(BadLength):
        CanFrame(0x009, bytes(8), dlc=7)


# --- unknown commands --------------------------------------------------------------------------------

@pytest.mark.parametrize("cmd", sorted(set(range(32)) - {int(c) for c in CommandId}))
def test_unimplemented_command_id_is_unknown_command(cmd):
    with pytest.raises(UnknownCommand):
        cs.decode(arbitration_id(0, cmd), bytes(8))


def test_unknown_command_is_reported_before_rtr_check():
    with pytest.raises(UnknownCommand):
        cs.decode(arbitration_id(0, 0x00), b"", is_remote=True)


# --- non-finite and out-of-range values ------------------------------------------------------------------

@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_encoding_a_non_finite_setpoint_is_refused(bad):
    with pytest.raises(NonFiniteValue):
        cs.SetInputVel(0, bad)


def test_decoding_a_nan_velocity_estimate_is_refused():
    with pytest.raises(NonFiniteValue):
        cs.decode(0x009, bytes(4) + NAN_BITS)


def test_decoding_an_infinite_torque_is_refused():
    with pytest.raises(NonFiniteValue):
        cs.decode(0x00E, INF_BITS + bytes(4))


def test_decoding_a_signalling_nan_bit_pattern_is_refused():
    with pytest.raises(NonFiniteValue):
        cs.decode(0x014, bytes.fromhex("0100807f") + bytes(4))


def test_setpoint_beyond_float32_range_is_out_of_range():
    with pytest.raises(OutOfRange):
        cs.SetInputTorque(0, 1e39)


def test_integer_setpoint_beyond_float_range_is_out_of_range():
    with pytest.raises(OutOfRange):
        cs.SetInputTorque(0, 10**400)


def test_negative_velocity_limit_is_out_of_range():
    with pytest.raises(OutOfRange):
        cs.SetLimits(0, -1.0, 10.0)


def test_decoding_a_negative_current_limit_is_out_of_range():
    with pytest.raises(OutOfRange):
        cs.decode(0x00F, struct.pack("<ff", 1.0, -2.0))


def test_decoding_an_unknown_axis_state_is_out_of_range():
    with pytest.raises(OutOfRange):
        cs.decode(0x001, struct.pack("<IBBBx", 0, 200, 0, 0))


def test_decoding_an_unknown_control_mode_is_out_of_range():
    with pytest.raises(OutOfRange):
        cs.decode(0x00B, struct.pack("<II", 7, 1))


def test_decoding_identify_2_is_out_of_range():
    with pytest.raises(OutOfRange):
        cs.decode(0x018, b"\x02")


def test_requested_state_15_is_out_of_range():
    with pytest.raises(OutOfRange):
        cs.SetAxisState(0, 15)


# --- wrong types ---------------------------------------------------------------------------------------------

def test_string_setpoint_is_wrong_type():
    with pytest.raises(WrongType):
        cs.SetInputTorque(0, "1.0")


def test_bool_setpoint_is_wrong_type():
    with pytest.raises(WrongType):
        cs.SetInputTorque(0, True)


def test_int_identify_is_wrong_type():
    with pytest.raises(WrongType):
        cs.ClearErrors(0, identify=1)


def test_encoding_a_non_frame_object_is_wrong_type():
    with pytest.raises(WrongType):
        cs.encode("Estop")


def test_frame_data_given_as_str_is_wrong_type():
    with pytest.raises(WrongType):
        CanFrame(0x002, "")
