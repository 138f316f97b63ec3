"""The JSON form of a Zenoh sample: what a recording writes and the live view (`sharedctl foxglove`) sends.

One codec for both: a payload is decoded with the wire codec (``decode_message``, any array
lengths) and becomes the JSON of its MessagePack map (``to_map``) on the channel named by its
key, with the JSON Schema of its kind (:mod:`.json_schemas`); a payload the codec refuses becomes
a ``sharedctl.Undecoded`` record (key, error, size, the bytes in base64) on
:data:`~.json_schemas.UNDECODED_TOPIC`. Nothing here raises on bad input.

Times: ``log_time`` is the receiver's clock (Unix ns) when the sample arrived; ``publish_time`` the
Zenoh timestamp when the sender attached one, else the message's own ``send_time`` (an operator
command) or ``time`` (the others), in ns.
"""
from __future__ import annotations

import base64
import json
from dataclasses import dataclass
from typing import Any

from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.msgpack_codec import decode_message, to_map

from .json_schemas import MESSAGE_SCHEMAS, UNDECODED_SCHEMA, UNDECODED_SCHEMA_NAME, UNDECODED_TOPIC

_U64 = 1 << 64
MAX_ERROR_CHARS = 512


@dataclass(frozen=True, slots=True)
class JsonRecord:
    """One message on one channel: topic, kind (channel metadata), JSON Schema, JSON body, times in Unix ns."""

    topic: str
    kind: str                  # the wire kind (``robot_state`` …), else the schema's name
    schema: dict[str, Any]     # JSON Schema; ``schema["title"]`` is its name
    data: bytes                # the message as JSON
    log_time: int
    publish_time: int
    sequence: int = 0
    message: Any = None        # the decoded wire message; None for an undecoded payload or a derived record

    @property
    def schema_name(self) -> str:
        return self.schema["title"]


def zenoh_time_ns(timestamp) -> int | None:
    """A Zenoh ``Timestamp`` as Unix ns, or None when the sample carries none."""
    if timestamp is None:
        return None
    try:
        return int(timestamp.get_time().timestamp() * 1e9)
    except (AttributeError, ValueError, OverflowError, OSError):
        return None


def message_time_ns(message, fallback: int) -> int:
    """The message's own time (``send_time``, else ``time``) in ns, or ``fallback`` if it has none that fits."""
    seconds = getattr(message, "send_time", None)
    if seconds is None:
        seconds = getattr(message, "time", None)
    if seconds is None:
        return fallback
    ns = int(seconds * 1e9)
    return ns if 0 <= ns < _U64 else fallback


def wire_record(key: str, payload: bytes, log_ns: int, publish_ns: int | None = None) -> JsonRecord:
    """The JSON form of one received sample; a payload the codec refuses gives a ``sharedctl.Undecoded`` record."""
    try:
        message = decode_message(payload, None)
    except ProtocolError as exc:
        return undecoded_record(key, payload, log_ns, f"{type(exc).__name__}: {exc}")
    except Exception as exc:  # noqa: BLE001 — a codec bug must not lose the payload nor stop the receiver
        return undecoded_record(key, payload, log_ns, f"{type(exc).__name__}: {exc}")
    data = json.dumps(to_map(message), separators=(",", ":")).encode()
    publish = publish_ns if publish_ns is not None else message_time_ns(message, log_ns)
    return JsonRecord(key, message.KIND, MESSAGE_SCHEMAS[message.KIND], data, log_ns, publish,
                      getattr(message, "seq", 0) & 0xFFFFFFFF, message)


def undecoded_record(key: str, payload: bytes, log_ns: int, error: str) -> JsonRecord:
    data = json.dumps({"key": key, "error": error[:MAX_ERROR_CHARS], "size": len(payload),
                       "payload_base64": base64.b64encode(payload).decode()}).encode()
    return JsonRecord(UNDECODED_TOPIC, UNDECODED_SCHEMA_NAME, UNDECODED_SCHEMA, data, log_ns, log_ns)
