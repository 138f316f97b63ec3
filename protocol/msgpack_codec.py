"""MessagePack encoding of :mod:`.messages` for Zenoh payloads.

Payload: one MessagePack map with string keys::

    {"type": "<kind>", "version": [major, minor], <field>: <value>, ...}

Decoding is defensive: the byte length is bounded before anything is parsed,
MessagePack limits (string, binary, array, map and extension lengths) are set
so that no declared length can allocate more than the payload could hold,
extension types (including timestamps) are refused, keys must be unique
strings, and then every field goes through the message's validators. The
result is either a valid frozen message or a :class:`ProtocolError`.
"""
from __future__ import annotations

import enum
from typing import Any

import msgpack

from .errors import (
    MalformedPayload,
    MissingField,
    OversizedPayload,
    UnexpectedKind,
    UnknownKind,
    UnsupportedVersion,
    WrongType,
)
from .messages import KIND_TO_TYPE, MESSAGE_TYPES, WIRE_VERSION, LinkHealth, Message, check_dims
from .wire_types import ROBOT_DIMS, Dims

TYPE_KEY = "type"
VERSION_KEY = "version"
ENVELOPE_KEYS = frozenset({TYPE_KEY, VERSION_KEY})
MAX_PAYLOAD_BYTES = max(cls.MAX_BYTES for cls in MESSAGE_TYPES)
MAX_CONTAINER_LEN = 64      # entries of any array or map (schema needs at most 32 + envelope)
MAX_STRING_BYTES = 1024     # UTF-8 bytes of any string (256 chars x 4 bytes)

assert not any(ENVELOPE_KEYS & {name for name, _, _ in cls.WIRE_FIELDS} for cls in MESSAGE_TYPES)


def _pairs_to_map(pairs: list[tuple[Any, Any]]) -> dict[str, Any]:
    result: dict[str, Any] = {}
    for key, value in pairs:
        if not isinstance(key, str):
            raise MalformedPayload("map keys must be strings")
        if key in result:
            raise MalformedPayload(f"duplicate key {key[:32]!r}")
        result[key] = value
    return result


def _refuse_extension(code: int, data: bytes) -> Any:
    raise MalformedPayload(f"MessagePack extension type {code} is not allowed")


def _unpack(payload: bytes) -> Any:
    try:
        return msgpack.unpackb(
            payload,
            raw=False,
            strict_map_key=True,
            use_list=True,
            timestamp=0,
            object_pairs_hook=_pairs_to_map,
            ext_hook=_refuse_extension,
            max_str_len=MAX_STRING_BYTES,
            max_bin_len=MAX_STRING_BYTES,
            max_array_len=MAX_CONTAINER_LEN,
            max_map_len=MAX_CONTAINER_LEN,
            max_ext_len=0,
        )
    except MalformedPayload:
        raise
    except (msgpack.UnpackException, ValueError, TypeError, OverflowError, RecursionError) as exc:
        raise MalformedPayload(f"not a valid MessagePack payload: {type(exc).__name__}") from None


def _check_version(value: Any) -> tuple[int, int]:
    if not isinstance(value, list) or len(value) != 2:
        raise WrongType("version must be [major, minor]")
    major, minor = value
    if any(isinstance(v, bool) or not isinstance(v, int) or v < 0 for v in (major, minor)):
        raise WrongType("version entries must be unsigned integers")
    if major != WIRE_VERSION[0]:
        raise UnsupportedVersion(f"wire version {major}.{minor}; this peer speaks {WIRE_VERSION[0]}.x")
    return major, minor


def _to_wire(value: Any) -> Any:
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, tuple):
        return [_to_wire(v) for v in value]
    if isinstance(value, LinkHealth):
        return {name: getattr(value, name) for name, _, _ in LinkHealth.WIRE_FIELDS}
    return value


def to_map(message: Message) -> dict[str, Any]:
    """The MessagePack map of ``message`` (envelope included), before packing."""
    cls = type(message)
    if cls not in KIND_TO_TYPE.values():
        raise WrongType(f"{cls.__name__} is not a wire message")
    body = {TYPE_KEY: cls.KIND, VERSION_KEY: list(WIRE_VERSION)}
    for name, _, _ in cls.WIRE_FIELDS:
        body[name] = _to_wire(getattr(message, name))
    return body


def encode_message(message: Message, dims: Dims | None = None) -> bytes:
    """Encode a message; with ``dims``, refuse arrays of other lengths (:class:`WrongLength`)."""
    cls = type(message)
    if cls not in KIND_TO_TYPE.values():
        raise WrongType(f"{cls.__name__} is not a wire message")
    cls(**{name: getattr(message, name) for name, _, _ in cls.WIRE_FIELDS})  # re-validate
    if dims is not None:
        check_dims(message, dims)
    payload = msgpack.packb(to_map(message), use_bin_type=True, use_single_float=False)
    if len(payload) > cls.MAX_BYTES:
        raise OversizedPayload(f"{cls.KIND} encodes to {len(payload)} bytes > {cls.MAX_BYTES}")
    return payload


def decode_message(payload: bytes, dims: Dims | None = ROBOT_DIMS, *, expect: type | None = None) -> Message:
    """Decode a payload to a typed message or raise a :class:`ProtocolError`.

    ``dims`` are the receiver's array lengths (``None`` accepts any valid
    lengths); ``expect`` restricts the accepted message class
    (:class:`UnexpectedKind` otherwise).
    """
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise WrongType("payload must be bytes")
    size = len(payload)
    if size > MAX_PAYLOAD_BYTES:
        raise OversizedPayload(f"{size} bytes > {MAX_PAYLOAD_BYTES}")
    body = _unpack(payload)
    if not isinstance(body, dict):
        raise MalformedPayload("top level must be a map")
    if VERSION_KEY not in body:
        raise MissingField("version is missing")
    _check_version(body[VERSION_KEY])
    if TYPE_KEY not in body:
        raise MissingField("type is missing")
    kind = body[TYPE_KEY]
    if not isinstance(kind, str):
        raise WrongType("type must be a string")
    cls = KIND_TO_TYPE.get(kind)
    if cls is None:
        raise UnknownKind(f"unknown message type {kind[:32]!r}")
    if size > cls.MAX_BYTES:
        raise OversizedPayload(f"{kind} of {size} bytes > {cls.MAX_BYTES}")
    if expect is not None and cls is not expect:
        raise UnexpectedKind(f"expected {expect.KIND}, got {kind}")
    values = {}
    for name, _, _ in cls.WIRE_FIELDS:
        if name in body:
            values[name] = body[name]
        elif name not in cls.WIRE_DEFAULTS:     # a field added by a later minor may be absent
            raise MissingField(f"{kind}.{name} is missing")
    message = cls(**values)  # validates every field; unknown keys were ignored
    if dims is not None:
        check_dims(message, dims)
    return message
