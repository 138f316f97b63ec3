"""Wire contract of sharedctl: CAN (ODrive CANSimple) and Zenoh (MessagePack) codecs. Pure.

Modules
-------
``cansimple``      typed ODrive CANSimple 0.6 frames <-> :class:`CanFrame` (``encode``, ``decode_frame``, ``poll``;
                   per period: ``torque_frame``, ``periodic_kind``, ``encoder_estimates``)
``cancodec``       a frame kind's signal table compiled once into a ``struct.Struct`` codec
``canframe``       the raw frame and the ``node_id << 5 | cmd_id`` id layout
``odrive_enums``   AxisState, ControlMode, InputMode, ProcedureResult, ODriveError, CommandId
``dbc``            generator of ``odrive_cansimple.dbc`` from the codec table
``messages``       OperatorCommand, RobotState, Event, Heartbeat, LeaseRequest/Reply, GroundTruth
``msgpack_codec``  ``encode_message`` / ``decode_message`` (bounded, versioned MessagePack)
``keys``           Zenoh key expressions ``sharedctl/v1/<robot>/...``
``rmw_zenoh``      rmw_zenoh's topic keys, liveliness tokens and attachment; the pinned Jazzy type hashes
``ros2_messages``  RobotState → nav_msgs/msg/Odometry, std_msgs/msg/String; CDR → geometry_msgs/msg/Twist (rosbags)
``errors``         the typed errors (all subclasses of :class:`ProtocolError`)
``fuzz``           seeded fuzz campaign used by the tests and ``sharedctl fuzz``

Bytes in, typed values or typed errors out: no sockets, clocks or printing here.
The specification is protocol/README.md.
"""
from .canframe import DEFAULT_WHEEL_NODES, CanFrame
from .errors import (
    BadArbitrationId,
    BadLength,
    BadNodeId,
    FrameError,
    KeyExprError,
    MalformedPayload,
    MessageError,
    MissingField,
    NonFiniteValue,
    OutOfRange,
    OversizedPayload,
    ProtocolError,
    UnexpectedKind,
    UnexpectedRemote,
    UnknownCommand,
    UnknownKind,
    UnsupportedVersion,
    WrongLength,
    WrongType,
)
from .messages import WIRE_VERSION
from .msgpack_codec import decode_message, encode_message
from .wire_types import ROBOT_DIMS, Dims

__all__ = [
    "DEFAULT_WHEEL_NODES", "ROBOT_DIMS", "WIRE_VERSION", "BadArbitrationId", "BadLength", "BadNodeId",
    "CanFrame", "Dims", "FrameError", "KeyExprError", "MalformedPayload", "MessageError", "MissingField",
    "NonFiniteValue", "OutOfRange", "OversizedPayload", "ProtocolError", "UnexpectedKind", "UnexpectedRemote",
    "UnknownCommand", "UnknownKind", "UnsupportedVersion", "WrongLength", "WrongType", "decode_message",
    "encode_message",
]
