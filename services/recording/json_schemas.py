"""JSON Schemas of the wire messages, for MCAP channels that Foxglove can read.

A recorded message is the JSON form of its MessagePack map (``to_map``: the envelope
``type`` and ``version`` and every field, enums as their strings, ``link`` as a nested
object), so one schema per message kind describes every message on a channel. The schemas
are derived from the message dataclasses' annotations, so a field added to a message is in
its schema without an edit here.

Payloads that do not decode are kept on their own channel (:data:`UNDECODED_TOPIC`) with the
schema :data:`UNDECODED_SCHEMA`: the key, the decoder's error and the bytes in base64.
"""
from __future__ import annotations

import enum
import json
import types
import typing
from typing import Any

from sharedctl.protocol.messages import MESSAGE_TYPES

SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
UNDECODED_TOPIC = "sharedctl/undecoded"
VIEW_PREFIX = "sharedctl/view"       # derived views (foxglove.Log, foxglove.SceneUpdate): topics, never Zenoh keys
UNDECODED_SCHEMA_NAME = "sharedctl.Undecoded"

UNDECODED_SCHEMA: dict[str, Any] = {
    "title": UNDECODED_SCHEMA_NAME,
    "description": "A payload received on a sharedctl key that the wire codec refused; kept byte for byte.",
    "type": "object",
    "properties": {
        "key": {"type": "string", "description": "Zenoh key expression it arrived on"},
        "error": {"type": "string", "description": "ProtocolError class and message"},
        "size": {"type": "integer", "description": "payload length, bytes"},
        "payload_base64": {"type": "string", "contentEncoding": "base64"},
    },
    "required": ["key", "error", "size", "payload_base64"],
}


def _json_type(hint: Any) -> dict[str, Any]:
    """The JSON Schema of one annotated field type."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        options = [_json_type(arg) for arg in typing.get_args(hint)]
        return {"anyOf": options}
    if origin is tuple:
        item = typing.get_args(hint)[0]
        return {"type": "array", "items": _json_type(item)}
    if hint is type(None):
        return {"type": "null"}
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        return {"type": "string", "enum": [member.value for member in hint]}
    if hint is bool:
        return {"type": "boolean"}
    if hint is int:
        return {"type": "integer"}
    if hint is float:
        return {"type": "number"}
    if hint is str:
        return {"type": "string"}
    if hasattr(hint, "WIRE_FIELDS"):
        return object_schema(hint)
    raise TypeError(f"no JSON Schema for {hint!r}")


def object_schema(cls: type) -> dict[str, Any]:
    """Properties of a wire record (message or nested record), every field required."""
    hints = typing.get_type_hints(cls)
    names = [name for name, _, _ in cls.WIRE_FIELDS]
    return {"type": "object", "properties": {name: _json_type(hints[name]) for name in names}, "required": names}


def message_schema(cls: type) -> dict[str, Any]:
    """The schema of one message kind, envelope included."""
    schema = object_schema(cls)
    schema["properties"] = {
        "type": {"type": "string", "const": cls.KIND},
        "version": {"type": "array", "items": {"type": "integer"}, "minItems": 2, "maxItems": 2},
        **schema["properties"],
    }
    schema["required"] = ["type", "version", *schema["required"]]
    return {"title": schema_name(cls), "description": (cls.__doc__ or "").strip().splitlines()[0], **schema}


def schema_name(cls: type) -> str:
    """``sharedctl.RobotState`` etc."""
    return f"sharedctl.{cls.__name__}"


def schema_bytes(schema: dict[str, Any]) -> bytes:
    return json.dumps(schema, separators=(",", ":")).encode()


#: kind tag (``robot_state`` …) -> JSON Schema
MESSAGE_SCHEMAS: dict[str, dict[str, Any]] = {cls.KIND: message_schema(cls) for cls in MESSAGE_TYPES}
