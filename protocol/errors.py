"""Typed errors of the wire protocol.

Every decoder in :mod:`sharedctl.protocol` either returns a valid typed value or
raises a subclass of :class:`ProtocolError`; encoders and message constructors
raise the same errors for values that must never reach the wire.

Hierarchy::

    ProtocolError (ValueError)
    ├── NonFiniteValue        NaN or ±inf (CAN float32 or MessagePack float)
    ├── OutOfRange            finite but outside the field's bounds / enum set
    ├── WrongType             a value of the wrong type (bool where float, ...)
    ├── WrongLength           an array or string of the wrong length
    ├── FrameError            CAN (ODrive CANSimple) frame level
    │   ├── BadArbitrationId  extended id, or id outside 11 bits
    │   ├── BadNodeId         node id outside 0..63 or not a configured node
    │   ├── UnknownCommand    command id this codec does not implement
    │   ├── BadLength         DLC differs from the published DBC length
    │   └── UnexpectedRemote  RTR on a frame that cannot be polled
    ├── MessageError          Zenoh payload (MessagePack) level
    │   ├── MalformedPayload  not MessagePack / not a map / duplicate or non-str key
    │   ├── OversizedPayload  more bytes than the kind's bound
    │   ├── UnsupportedVersion  wire major differs from ours
    │   ├── UnknownKind       kind tag we do not know
    │   ├── UnexpectedKind    a valid message of another kind than asked for
    │   ├── MissingField      a required field is absent
    │   ├── BadAttachment     an attachment that cannot be read (operator signature, rmw_zenoh's)
    │   └── BadCdr            a ROS 2 CDR payload that cannot be decoded, or values no robot can take
    └── KeyExprError          Zenoh key expression or id/role token
"""
from __future__ import annotations


class ProtocolError(ValueError):
    """Base of every error raised by the protocol package."""


class NonFiniteValue(ProtocolError):
    """A float is NaN or infinite; such values never go on or come off the wire."""


class OutOfRange(ProtocolError):
    """A value is of the right type but outside its documented bounds or enum set."""


class WrongType(ProtocolError):
    """A value has the wrong type (for example a string where a float belongs)."""


class WrongLength(ProtocolError):
    """An array (or string) does not have the length the schema requires."""


class FrameError(ProtocolError):
    """A CAN frame cannot be encoded or decoded."""


class BadArbitrationId(FrameError):
    """The arbitration id is extended (29-bit) or does not fit in 11 bits."""


class BadNodeId(FrameError):
    """The node id is outside 0..63 or not among the configured nodes."""


class UnknownCommand(FrameError):
    """The command id (low 5 bits of the arbitration id) is not implemented."""


class BadLength(FrameError):
    """The frame's DLC is not the one the DBC specifies for this command."""


class UnexpectedRemote(FrameError):
    """A remote (RTR) frame names a command that is not a Get_* message."""


class MessageError(ProtocolError):
    """A MessagePack payload cannot be encoded or decoded."""


class MalformedPayload(MessageError):
    """Not valid MessagePack, not a map at top level, or a forbidden construct."""


class OversizedPayload(MessageError):
    """The payload is larger than the bound for its kind."""


class UnsupportedVersion(MessageError):
    """The payload's wire major version differs from this implementation's."""


class UnknownKind(MessageError):
    """The payload's kind tag names no message kind we know."""


class UnexpectedKind(MessageError):
    """A valid payload of another kind than the one the caller asked for."""


class MissingField(MessageError):
    """A required field is absent from the payload."""


class BadAttachment(MessageError):
    """An attachment that is not one: an operator signature (protocol/signature.py) or rmw_zenoh's publication
    attachment (protocol/rmw_zenoh.py): size, encoding, fields."""


class BadCdr(MessageError):
    """A ROS 2 message (CDR, protocol/ros2_messages.py) that cannot be decoded, or whose values are not finite or
    beyond what any robot can be asked (a Twist of 1e6 m/s)."""


class KeyExprError(ProtocolError):
    """A key expression, robot id or role is malformed."""
