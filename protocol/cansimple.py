"""ODrive CANSimple (firmware 0.6 layout) codec: typed frames <-> :class:`CanFrame`.

One table (:data:`FRAME_SPECS`) describes every implemented command: DBC name,
command id, DLC, sender and signals (start bit, length, type, unit). The codec,
the DBC generator (:mod:`.dbc`) and protocol/README.md all follow that table.
Each kind's entry is compiled once, at import, into a :class:`~.cancodec.FrameCodec`
(:data:`CODECS`, one `struct.Struct` per kind); :func:`encode`, :func:`decode_frame`
and the per-period entry points use these and nothing else.

Per-period entry points (the frames of every control period, without a typed frame):
:func:`torque_frame` gives the id and bytes of Set_Input_Torque; :func:`periodic_kind`
tells a Set_Input_Torque or a Get_Encoder_Estimates that :func:`decode` would accept
from everything else (which goes to :func:`decode`, to be decoded or refused);
:data:`encoder_estimates` reads the estimate's values.

Rules
-----
* Little-endian (Intel) signals; floats are IEEE-754 float32.
* Float fields are rounded to float32 when a typed frame is built, so a typed
  frame equals what the bus carries; NaN/inf are refused (:class:`NonFiniteValue`),
  magnitudes beyond float32 are :class:`OutOfRange`.
* Data frames must have exactly the DLC of ODrive's published DBC
  (:class:`BadLength`); unused bits are written as zero and ignored on decode.
* Get_* commands may be polled with a remote (RTR) frame of DLC 0 or the DBC DLC;
  decoding such a frame yields :class:`PollRequest`. RTR on anything else is
  :class:`UnexpectedRemote`.
"""
from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, fields
from math import isfinite

from .cancodec import FrameCodec
from .canframe import (
    MAX_CMD_ID,
    MAX_NODE_ID,
    MAX_STANDARD_ID,
    CanFrame,
    arbitration_id,
    check_node_id,
    split_arbitration_id,
)
from .canspec import FrameSpec, SignalKind, SignalSpec, to_float32 as to_float32  # to_float32: re-exported
from .errors import BadArbitrationId, BadLength, BadNodeId, UnexpectedRemote, UnknownCommand, WrongType
from .odrive_enums import AxisState, CommandId, ControlMode, InputMode, ODriveError, ProcedureResult

def _normalize(frame: object) -> None:
    object.__setattr__(frame, "node_id", check_node_id(frame.node_id))
    for sig in FRAME_SPECS[type(frame)].signals:
        object.__setattr__(frame, sig.attr, sig.coerce(getattr(frame, sig.attr)))


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """0x01 ODrive -> host, cyclic: axis error bits, state, procedure result, trajectory done."""

    node_id: int
    axis_error: ODriveError = ODriveError.NONE
    axis_state: AxisState = AxisState.IDLE
    procedure_result: ProcedureResult = ProcedureResult.SUCCESS
    trajectory_done: bool = False

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class Estop:
    """0x02 host -> ODrive, DLC 0: disarm the axis with ESTOP_REQUESTED."""

    node_id: int

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class GetError:
    """0x03 ODrive -> host: active errors and the reason of the last disarm."""

    node_id: int
    active_errors: ODriveError = ODriveError.NONE
    disarm_reason: ODriveError = ODriveError.NONE

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class SetAxisState:
    """0x07 host -> ODrive: request an axis state (e.g. CLOSED_LOOP_CONTROL, IDLE)."""

    node_id: int
    requested_state: AxisState

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class GetEncoderEstimates:
    """0x09 ODrive -> host, cyclic: position [turns] and velocity [turns/s] estimates."""

    node_id: int
    pos_estimate: float
    vel_estimate: float

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class SetControllerMode:
    """0x0B host -> ODrive: control mode and input mode."""

    node_id: int
    control_mode: ControlMode
    input_mode: InputMode

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class SetInputVel:
    """0x0D host -> ODrive: velocity setpoint [turns/s] and torque feed-forward [Nm]."""

    node_id: int
    input_vel: float
    input_torque_ff: float = 0.0

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class SetInputTorque:
    """0x0E host -> ODrive: torque setpoint [Nm]."""

    node_id: int
    input_torque: float

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class SetLimits:
    """0x0F host -> ODrive: velocity limit [turns/s] and current limit [A], both >= 0."""

    node_id: int
    velocity_limit: float
    current_limit: float

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class GetIq:
    """0x14 ODrive -> host: q-axis current setpoint and measurement [A]."""

    node_id: int
    iq_setpoint: float
    iq_measured: float

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class GetBusVoltageCurrent:
    """0x17 ODrive -> host: DC bus voltage [V] and current [A]."""

    node_id: int
    bus_voltage: float
    bus_current: float

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class ClearErrors:
    """0x18 host -> ODrive, DLC 1: clear errors (and leave ESTOP); identify blinks the LED."""

    node_id: int
    identify: bool = False

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class GetTorques:
    """0x1C ODrive -> host: torque target and torque estimate [Nm]."""

    node_id: int
    torque_target: float
    torque_estimate: float

    def __post_init__(self) -> None:
        _normalize(self)


@dataclass(frozen=True, slots=True)
class PollRequest:
    """A remote (RTR) frame asking node ``node_id`` to send its ``command`` (a Get_* frame)."""

    node_id: int
    command: CommandId
    dlc: int = 8

    def __post_init__(self) -> None:
        object.__setattr__(self, "node_id", check_node_id(self.node_id))
        if isinstance(self.command, bool) or not isinstance(self.command, int):
            raise WrongType("command must be a CommandId")
        try:
            command = CommandId(self.command)
        except ValueError:
            raise UnknownCommand(f"command id {self.command!r} is not implemented") from None
        spec = SPEC_BY_CMD[command]
        if not spec.pollable:
            raise UnexpectedRemote(f"{spec.name} cannot be polled with RTR")
        if isinstance(self.dlc, bool) or not isinstance(self.dlc, int):
            raise WrongType("dlc must be an int")
        if self.dlc not in (0, spec.dlc):
            raise BadLength(f"RTR for {spec.name} must have DLC 0 or {spec.dlc}")
        object.__setattr__(self, "command", command)


CanMessage = (
    Heartbeat | Estop | GetError | SetAxisState | GetEncoderEstimates | SetControllerMode
    | SetInputVel | SetInputTorque | SetLimits | GetIq | GetBusVoltageCurrent | ClearErrors
    | GetTorques | PollRequest
)


def _f(name: str, attr: str, start: int, unit: str, minimum: float | None = None) -> SignalSpec:
    return SignalSpec(name, attr, start, 32, "float", unit, None, minimum)


def _u(name: str, attr: str, start: int, length: int, kind: SignalKind, enum: type | None = None) -> SignalSpec:
    return SignalSpec(name, attr, start, length, kind, "", enum)


_C = CommandId
FRAME_SPECS: dict[type, FrameSpec] = {
    Heartbeat: FrameSpec(_C.HEARTBEAT, "Heartbeat", 8, "odrive", (
        _u("Axis_Error", "axis_error", 0, 32, "flag", ODriveError),
        _u("Axis_State", "axis_state", 32, 8, "enum", AxisState),
        _u("Procedure_Result", "procedure_result", 40, 8, "enum", ProcedureResult),
        _u("Trajectory_Done_Flag", "trajectory_done", 48, 1, "bool"),
    ), "Cyclic status of the axis."),
    Estop: FrameSpec(_C.ESTOP, "Estop", 0, "host", (), "Disarm the axis (ESTOP_REQUESTED)."),
    GetError: FrameSpec(_C.GET_ERROR, "Get_Error", 8, "odrive", (
        _u("Active_Errors", "active_errors", 0, 32, "flag", ODriveError),
        _u("Disarm_Reason", "disarm_reason", 32, 32, "flag", ODriveError),
    ), "Active errors and the error that caused the last disarm."),
    SetAxisState: FrameSpec(_C.SET_AXIS_STATE, "Set_Axis_State", 8, "host", (
        _u("Axis_Requested_State", "requested_state", 0, 32, "enum", AxisState),
    ), "Request an axis state."),
    GetEncoderEstimates: FrameSpec(_C.GET_ENCODER_ESTIMATES, "Get_Encoder_Estimates", 8, "odrive", (
        _f("Pos_Estimate", "pos_estimate", 0, "rev"),
        _f("Vel_Estimate", "vel_estimate", 32, "rev/s"),
    ), "Position and velocity estimates."),
    SetControllerMode: FrameSpec(_C.SET_CONTROLLER_MODE, "Set_Controller_Mode", 8, "host", (
        _u("Control_Mode", "control_mode", 0, 32, "enum", ControlMode),
        _u("Input_Mode", "input_mode", 32, 32, "enum", InputMode),
    ), "Set control mode and input mode."),
    SetInputVel: FrameSpec(_C.SET_INPUT_VEL, "Set_Input_Vel", 8, "host", (
        _f("Input_Vel", "input_vel", 0, "rev/s"),
        _f("Input_Torque_FF", "input_torque_ff", 32, "Nm"),
    ), "Velocity setpoint with torque feed-forward."),
    SetInputTorque: FrameSpec(_C.SET_INPUT_TORQUE, "Set_Input_Torque", 8, "host", (
        _f("Input_Torque", "input_torque", 0, "Nm"),
    ), "Torque setpoint."),
    SetLimits: FrameSpec(_C.SET_LIMITS, "Set_Limits", 8, "host", (
        _f("Velocity_Limit", "velocity_limit", 0, "rev/s", 0.0),
        _f("Current_Limit", "current_limit", 32, "A", 0.0),
    ), "Velocity and current limits (sharedctl refuses negative limits)."),
    GetIq: FrameSpec(_C.GET_IQ, "Get_Iq", 8, "odrive", (
        _f("Iq_Setpoint", "iq_setpoint", 0, "A"),
        _f("Iq_Measured", "iq_measured", 32, "A"),
    ), "q-axis current setpoint and measurement."),
    GetBusVoltageCurrent: FrameSpec(_C.GET_BUS_VOLTAGE_CURRENT, "Get_Bus_Voltage_Current", 8, "odrive", (
        _f("Bus_Voltage", "bus_voltage", 0, "V"),
        _f("Bus_Current", "bus_current", 32, "A"),
    ), "DC bus voltage and current."),
    ClearErrors: FrameSpec(_C.CLEAR_ERRORS, "Clear_Errors", 1, "host", (
        _u("Identify", "identify", 0, 8, "bool"),
    ), "Clear errors; Identify=1 also blinks the LED (sharedctl accepts only 0 or 1)."),
    GetTorques: FrameSpec(_C.GET_TORQUES, "Get_Torques", 8, "odrive", (
        _f("Torque_Target", "torque_target", 0, "Nm"),
        _f("Torque_Estimate", "torque_estimate", 32, "Nm"),
    ), "Torque target and torque estimate."),
}
SPEC_BY_CMD: dict[CommandId, FrameSpec] = {spec.cmd: spec for spec in FRAME_SPECS.values()}
CLASS_BY_CMD: dict[int, type] = {int(spec.cmd): cls for cls, spec in FRAME_SPECS.items()}
POLLABLE_COMMANDS: frozenset[CommandId] = frozenset(s.cmd for s in FRAME_SPECS.values() if s.pollable)

assert all(  # the table and the dataclasses describe the same fields
    [f.name for f in fields(cls)][1:] == [s.attr for s in spec.signals] for cls, spec in FRAME_SPECS.items()
)


#: each kind's codec, compiled once from its table entry; `encode`, `decode_frame` and the
#: per-period entry points below all go through these
CODECS: dict[type, FrameCodec] = {cls: FrameCodec(spec) for cls, spec in FRAME_SPECS.items()}


def encode(message: CanMessage) -> CanFrame:
    """Encode a typed frame (or :class:`PollRequest`) as a :class:`CanFrame`."""
    if isinstance(message, PollRequest):
        return CanFrame(arbitration_id(message.node_id, message.command), b"", True, message.dlc)
    codec = CODECS.get(type(message))
    if codec is None:
        raise WrongType(f"{type(message).__name__} is not a CANSimple frame type")
    # values were validated when the frame was built; the codec checks them again
    return CanFrame(arbitration_id(message.node_id, codec.spec.cmd), codec.pack(codec.values_of(message)))


def poll(node_id: int, command: CommandId, dlc: int = 8) -> CanFrame:
    """RTR frame requesting the Get_* ``command`` from ``node_id``."""
    return encode(PollRequest(node_id, command, dlc))


def decode_frame(frame: CanFrame, *, nodes: Collection[int] | None = None) -> CanMessage:
    """Decode a :class:`CanFrame` to a typed frame, or raise a :class:`ProtocolError`.

    ``nodes`` restricts the accepted node ids (e.g. :data:`DEFAULT_WHEEL_NODES`);
    ``None`` accepts 0..63.
    """
    if not isinstance(frame, CanFrame):
        raise WrongType("decode_frame takes a CanFrame")
    if frame.is_extended_id:
        raise BadArbitrationId("CANSimple uses 11-bit standard ids; got an extended id")
    node_id, cmd_id = split_arbitration_id(frame.arbitration_id)
    if nodes is not None and node_id not in nodes:
        raise BadNodeId(f"node {node_id} is not a configured node")
    cls = CLASS_BY_CMD.get(cmd_id)
    if cls is None:
        raise UnknownCommand(f"command id 0x{cmd_id:02X} is not implemented")
    codec = CODECS[cls]
    spec = codec.spec
    if frame.is_remote:
        if not spec.pollable:
            raise UnexpectedRemote(f"RTR on {spec.name}, which is not a Get_* frame")
        return PollRequest(node_id, spec.cmd, frame.dlc)
    if frame.dlc != spec.dlc:
        raise BadLength(f"{spec.name} has DLC {spec.dlc}, got {frame.dlc}")
    return cls(node_id, *codec.unpack(frame.data))


def decode(
    arbitration_id: int,
    data: bytes,
    is_remote: bool = False,
    *,
    dlc: int | None = None,
    is_extended_id: bool = False,
    nodes: Collection[int] | None = None,
) -> CanMessage:
    """Decode raw frame fields (as python-can's ``Message`` carries them)."""
    frame = CanFrame(arbitration_id, data, is_remote, dlc, is_extended_id)
    return decode_frame(frame, nodes=nodes)


# --- the frames of every control period ----------------------------------------------------------
# At 500 Hz the controller sends three Set_Input_Torque frames and reads three Get_Encoder_Estimates
# (and, on udp_multicast, its own three torque frames back): the entry points below handle exactly
# those through the same compiled codecs, without a typed frame per frame.

#: the kinds `periodic_kind` recognises. Set_Input_Torque carries one float32, Get_Encoder_Estimates
#: two, none with a minimum, DLC 8 (checked here): a frame of either is accepted by `decode`
#: exactly when its DLC is 8 and its values are finite
PERIODIC_KINDS: tuple[type, ...] = (SetInputTorque, GetEncoderEstimates)
assert [([(s.kind, s.minimum) for s in FRAME_SPECS[cls].signals], FRAME_SPECS[cls].dlc) for cls in PERIODIC_KINDS] \
    == [([("float", None)], 8), ([("float", None), ("float", None)], 8)]

_TORQUE_CMD = int(FRAME_SPECS[SetInputTorque].cmd)
_ENCODER_CMD = int(FRAME_SPECS[GetEncoderEstimates].cmd)
_TORQUE_IDS = {n: arbitration_id(n, _TORQUE_CMD) for n in range(MAX_NODE_ID + 1)}
_TORQUE_SIGNAL = FRAME_SPECS[SetInputTorque].signals[0]
_TORQUE_PACK = CODECS[SetInputTorque].layout.pack
_TORQUE_UNPACK = CODECS[SetInputTorque].layout.unpack


def torque_frame(node_id: int, torque: float) -> tuple[int, bytes]:
    """``(arbitration_id, data)`` of Set_Input_Torque ``torque`` [Nm] to ``node_id``: those of
    ``encode(SetInputTorque(node_id, torque))``, with the same typed errors (a NaN/inf torque is
    :class:`NonFiniteValue`, beyond float32 :class:`OutOfRange`, a bad node :class:`BadNodeId`)."""
    arb = _TORQUE_IDS.get(node_id) if type(node_id) is int else None
    if arb is None:
        arb = arbitration_id(node_id, _TORQUE_CMD)
    if type(torque) is float and isfinite(torque):
        try:
            return arb, _TORQUE_PACK(torque)      # rounds to float32 as `to_float32` does
        except OverflowError:
            pass
    return arb, _TORQUE_PACK(_TORQUE_SIGNAL.to_field(torque))    # anything else: the signal's own check


#: ``encoder_estimates(data) -> (pos_estimate turns, vel_estimate turns/s)``: the values ``decode``
#: gives the data of a frame `periodic_kind` called :class:`GetEncoderEstimates` (the compiled
#: codec's own unpack, without a call around it)
encoder_estimates = CODECS[GetEncoderEstimates].layout.unpack


def periodic_kind(arbitration_id: int, dlc: int, data: bytes, is_remote: bool = False,
                  is_extended_id: bool = False, nodes: Collection[int] | None = None) -> type | None:
    """:class:`SetInputTorque` or :class:`GetEncoderEstimates` if ``decode`` (same arguments) would
    return a frame of that kind, else None: every other frame, and every frame ``decode`` refuses,
    goes to ``decode``. Never raises. Fields of other types than the transports give (``data`` not
    ``bytes``, ``dlc`` or ``arbitration_id`` not ``int``) answer None, for ``decode`` to judge."""
    if (is_remote is not False or is_extended_id is not False or type(arbitration_id) is not int
            or type(data) is not bytes or type(dlc) is not int or dlc != 8 or len(data) != 8
            or not 0 <= arbitration_id <= MAX_STANDARD_ID
            or (nodes is not None and (arbitration_id >> 5) not in nodes)):
        return None
    cmd = arbitration_id & MAX_CMD_ID
    if cmd == _ENCODER_CMD:
        pos, vel = encoder_estimates(data)
        return GetEncoderEstimates if isfinite(pos) and isfinite(vel) else None
    if cmd == _TORQUE_CMD:
        return SetInputTorque if isfinite(_TORQUE_UNPACK(data)[0]) else None
    return None
