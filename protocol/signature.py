"""Operator signatures on the wire: the Zenoh attachment that carries one, and the bytes it covers.

An operator that signs its traffic sends, with every `OperatorCommand` put on
``…/operator/cmd`` and every `LeaseRequest` query on ``…/control/lease``, a Zenoh
**attachment** (the payload is unchanged, so recordings, relays and decoders that ignore
attachments see the same messages as before):

    attachment = MessagePack map {"v": 1, "signer": <operator id>, "sig": <64 bytes>}
    sig        = Ed25519 signature by the signer's key over signed_bytes(key_expr, payload)
    signed_bytes(key_expr, payload) = b"sharedctl/v1 operator signature\\0" + key_expr + b"\\0" + payload

The key expression is signed with the payload: a command signed for robot1 is not a valid
command for robot2, and a lease request is not a command. The signer is a token (the operator's
user name at the router and the `operator_id` its messages must carry). The signature says who
sent the bytes, not when: freshness and order stay the replay guard's business (the signed
payload carries the session, the sequence number and the send time, so a replayed signed
message is caught there). Which keys are trusted, and for which robots, is the receiver's
configuration (services/security/signing.py). Pure: no cryptography here, bytes only.
"""
from __future__ import annotations

from dataclasses import dataclass

import msgpack

from .errors import BadAttachment, ProtocolError
from .wire_types import check_token

ATTACHMENT_VERSION = 1
DOMAIN = b"sharedctl/v1 operator signature\x00"
SIGNATURE_LEN = 64            # Ed25519
MAX_ATTACHMENT = 256          # bytes; a valid attachment is < 100


@dataclass(frozen=True)
class Signature:
    """Who signed, and the signature's 64 bytes."""

    signer: str
    value: bytes


def signed_bytes(key_expr: str, payload: bytes) -> bytes:
    """What the signature covers: a domain tag, the key expression and the payload."""
    return DOMAIN + key_expr.encode() + b"\x00" + bytes(payload)


def encode_attachment(signer: str, value: bytes) -> bytes:
    """The attachment for `signer`'s signature `value` (raises `BadAttachment` on a bad signer or length)."""
    try:
        check_token(signer, "signer", BadAttachment)
    except ProtocolError as exc:
        raise BadAttachment(str(exc)) from None
    if len(value) != SIGNATURE_LEN:
        raise BadAttachment(f"a signature is {SIGNATURE_LEN} bytes, not {len(value)}")
    return msgpack.packb({"v": ATTACHMENT_VERSION, "signer": signer, "sig": bytes(value)}, use_bin_type=True)


def decode_attachment(data: bytes) -> Signature:
    """The signature an attachment carries; `BadAttachment` for anything else (size, MessagePack, fields)."""
    if len(data) > MAX_ATTACHMENT:
        raise BadAttachment(f"attachment of {len(data)} bytes (at most {MAX_ATTACHMENT})")
    try:
        fields = msgpack.unpackb(bytes(data), raw=False, strict_map_key=True, max_bin_len=MAX_ATTACHMENT,
                                 max_str_len=MAX_ATTACHMENT, max_array_len=8, max_map_len=8)
    except Exception as exc:  # noqa: BLE001 — msgpack raises several types for bad input
        raise BadAttachment(f"attachment is not MessagePack: {type(exc).__name__}") from None
    if not isinstance(fields, dict):
        raise BadAttachment("attachment is not a map")
    if fields.get("v") != ATTACHMENT_VERSION:
        raise BadAttachment(f"attachment version {fields.get('v')!r} (this side reads {ATTACHMENT_VERSION})")
    signer, value = fields.get("signer"), fields.get("sig")
    try:
        check_token(signer, "signer", BadAttachment)
    except ProtocolError as exc:
        raise BadAttachment(str(exc)) from None
    if not isinstance(value, bytes) or len(value) != SIGNATURE_LEN:
        raise BadAttachment(f"signature must be {SIGNATURE_LEN} bytes")
    return Signature(signer, value)
