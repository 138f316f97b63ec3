"""The committed DBC is the generated one, matches ODrive's published layout and agrees with the codec."""
from __future__ import annotations

import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol_strategies import data_frame_classes, frames_of
from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.canframe import CanFrame
from sharedctl.protocol.dbc import DBC_PATH, render_dbc

# Layout of ODrive's published odrive-cansimple-0.6.10.dbc for the frames sharedctl implements:
# name: (cmd id, DLC, sender, [(signal, start bit, length, is_float)]).
PUBLISHED_0_6 = {
    "Heartbeat": (0x01, 8, "ODrive", [("Axis_Error", 0, 32, False), ("Axis_State", 32, 8, False),
                                      ("Procedure_Result", 40, 8, False),
                                      ("Trajectory_Done_Flag", 48, 1, False)]),
    "Estop": (0x02, 0, "Master", []),
    "Get_Error": (0x03, 8, "ODrive", [("Active_Errors", 0, 32, False), ("Disarm_Reason", 32, 32, False)]),
    "Set_Axis_State": (0x07, 8, "Master", [("Axis_Requested_State", 0, 32, False)]),
    "Get_Encoder_Estimates": (0x09, 8, "ODrive", [("Pos_Estimate", 0, 32, True), ("Vel_Estimate", 32, 32, True)]),
    "Set_Controller_Mode": (0x0B, 8, "Master", [("Control_Mode", 0, 32, False), ("Input_Mode", 32, 32, False)]),
    "Set_Input_Vel": (0x0D, 8, "Master", [("Input_Vel", 0, 32, True), ("Input_Torque_FF", 32, 32, True)]),
    "Set_Input_Torque": (0x0E, 8, "Master", [("Input_Torque", 0, 32, True)]),
    "Set_Limits": (0x0F, 8, "Master", [("Velocity_Limit", 0, 32, True), ("Current_Limit", 32, 32, True)]),
    "Get_Iq": (0x14, 8, "ODrive", [("Iq_Setpoint", 0, 32, True), ("Iq_Measured", 32, 32, True)]),
    "Get_Bus_Voltage_Current": (0x17, 8, "ODrive", [("Bus_Voltage", 0, 32, True), ("Bus_Current", 32, 32, True)]),
    "Clear_Errors": (0x18, 1, "Master", [("Identify", 0, 8, False)]),
    "Get_Torques": (0x1C, 8, "ODrive", [("Torque_Target", 0, 32, True), ("Torque_Estimate", 32, 32, True)]),
}


@pytest.fixture(scope="module")
def db():
    return cantools.database.load_file(str(DBC_PATH))


def _signals_of(message):
    return sorted(
        ((s.name, s.start, s.length, s.is_float) for s in message.signals), key=lambda t: t[1]
    )


def test_committed_dbc_equals_the_generated_one():
    assert DBC_PATH.read_text(encoding="ascii") == render_dbc()


def test_dbc_lists_every_frame_for_nodes_0_1_2(db):
    expected = {f"Axis{n}_{name}" for n in (0, 1, 2) for name in PUBLISHED_0_6}
    assert {m.name for m in db.messages} == expected


@pytest.mark.parametrize("name", sorted(PUBLISHED_0_6))
@pytest.mark.parametrize("node", [0, 1, 2])
def test_dbc_message_has_published_id_length_sender_and_signals(db, name, node):
    cmd, dlc, sender, signals = PUBLISHED_0_6[name]
    message = db.get_message_by_name(f"Axis{node}_{name}")
    expected_sender = f"ODrive_Axis{node}" if sender == "ODrive" else "Master"
    assert (message.frame_id, message.length, message.senders, _signals_of(message)) == (
        node << 5 | cmd, dlc, [expected_sender], sorted(signals, key=lambda t: t[1]))


def test_dbc_signals_are_little_endian(db):
    assert {s.byte_order for m in db.messages for s in m.signals} == {"little_endian"}


def test_dbc_axis_state_value_table_names_closed_loop_control(db):
    signal = db.get_message_by_name("Axis0_Heartbeat").get_signal_by_name("Axis_State")
    assert signal.choices[8] == "CLOSED_LOOP_CONTROL"


def test_dbc_generated_for_other_nodes_uses_their_ids():
    other = cantools.database.load_string(render_dbc(nodes=(5,)), database_format="dbc")
    assert other.get_message_by_name("Axis5_Get_Encoder_Estimates").frame_id == 5 << 5 | 0x09


def _codec_values(message) -> dict[str, float | int]:
    spec = cs.FRAME_SPECS[type(message)]
    return {sig.name: (float(v) if sig.kind == "float" else int(v))
            for sig in spec.signals for v in [getattr(message, sig.attr)]}


def _dbc_for(db, frame_id):
    return db.get_message_by_frame_id(frame_id)


def _frames_on_dbc_nodes(cls):
    return frames_of(cls, nodes=st.sampled_from([0, 1, 2]))


@pytest.mark.parametrize("cls", data_frame_classes, ids=lambda c: c.__name__)
def test_cantools_decodes_every_codec_frame_to_the_same_values(db, cls):
    @given(_frames_on_dbc_nodes(cls))
    def check(message):
        frame = cs.encode(message)
        decoded = _dbc_for(db, frame.arbitration_id).decode(frame.data, decode_choices=False)
        assert decoded == _codec_values(message)

    check()


def _dbc_values(sig: cs.SignalSpec) -> st.SearchStrategy:
    if sig.kind == "float":
        return st.floats(min_value=sig.minimum, width=32, allow_nan=False, allow_infinity=False)
    if sig.kind == "bool":
        return st.integers(0, 1)
    if sig.kind == "flag":
        return st.integers(0, 2**32 - 1)
    return st.sampled_from([int(m) for m in sig.enum])


@pytest.mark.parametrize("cls", data_frame_classes, ids=lambda c: c.__name__)
def test_codec_decodes_every_cantools_frame_to_the_same_values(db, cls):
    spec = cs.FRAME_SPECS[cls]
    values = st.fixed_dictionaries({sig.name: _dbc_values(sig) for sig in spec.signals})

    @given(st.sampled_from([0, 1, 2]), values)
    def check(node, signal_values):
        message = db.get_message_by_name(f"Axis{node}_{spec.name}")
        frame = CanFrame(message.frame_id, message.encode(signal_values))
        decoded = cs.decode_frame(frame)
        assert (decoded.node_id, _codec_values(decoded)) == (node, signal_values)

    check()

