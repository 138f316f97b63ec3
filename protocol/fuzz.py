"""Fuzz campaign over the protocol decoders (pure: seeded generator in, report out).

Each decoder gets random and mutated inputs. An input either decodes to a valid
typed value (checked independently: every float finite, every array of the
receiver's length) or raises a :class:`ProtocolError`; anything else is an
*escape*. Used by the test suite and by ``sharedctl fuzz``.
"""
from __future__ import annotations

import math
import random
import struct
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import msgpack

from . import cansimple as cs
from .errors import ProtocolError
from .keys import KINDS, PREFIX, ParsedKey, parse_key
from .messages import (
    MESSAGE_TYPES,
    Authority,
    ControlRequest,
    EventKind,
    LeaseAction,
    LinkHealth,
    SetClass,
    Severity,
    shape_of,
)
from .msgpack_codec import decode_message, encode_message, to_map
from .signature import SIGNATURE_LEN, Signature, decode_attachment, encode_attachment
from .wire_types import ROBOT_DIMS, TOKEN_PATTERN

DECODERS = ("can", "message", "key", "attachment")


@dataclass
class FuzzReport:
    """Outcome of fuzzing one decoder."""

    decoder: str
    inputs: int = 0
    typed_errors: int = 0
    accepted: int = 0
    escapes: int = 0
    examples: list[str] = field(default_factory=list)   # first escapes, for diagnosis
    errors: Counter = field(default_factory=Counter)     # typed error class -> count

    @property
    def ok(self) -> bool:
        return self.escapes == 0


# --- independent checks of accepted outputs ------------------------------------------------------

def _finite_everywhere(value: Any) -> bool:
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, tuple):
        return all(_finite_everywhere(v) for v in value)
    if hasattr(value, "__dataclass_fields__"):
        return all(_finite_everywhere(getattr(value, name)) for name in value.__dataclass_fields__)
    return True


def is_valid_can_output(decoded: Any) -> bool:
    """A decoded CAN value is a known frame type with a node in 0..63 and only finite floats."""
    return (type(decoded) in (*cs.FRAME_SPECS, cs.PollRequest)
            and 0 <= decoded.node_id <= 63 and _finite_everywhere(decoded))


def is_valid_message_output(decoded: Any) -> bool:
    """A decoded message is a known type, finite everywhere, with the project's array lengths."""
    if type(decoded) not in MESSAGE_TYPES or not _finite_everywhere(decoded):
        return False
    return all(length == getattr(ROBOT_DIMS, dim) for dim, length in shape_of(decoded).items())


def is_valid_key_output(decoded: Any) -> bool:
    """A parsed key names a known kind and a robot id without separators."""
    return isinstance(decoded, ParsedKey) and decoded.kind in KINDS and "/" not in decoded.robot


# --- valid samples -----------------------------------------------------------------------------

def _f32(rng: random.Random) -> float:
    return struct.unpack("<f", struct.pack("<f", rng.uniform(-1e3, 1e3)))[0]


def random_can_message(rng: random.Random) -> Any:
    """A random valid typed CANSimple frame (or poll request)."""
    classes = [*cs.FRAME_SPECS, cs.PollRequest]
    cls = rng.choice(classes)
    node = rng.randrange(64)
    if cls is cs.PollRequest:
        return cs.PollRequest(node, rng.choice(sorted(cs.POLLABLE_COMMANDS)), rng.choice((0, 8)))
    values = []
    for sig in cs.FRAME_SPECS[cls].signals:
        if sig.kind == "float":
            values.append(abs(_f32(rng)) if sig.minimum is not None else _f32(rng))
        elif sig.kind == "bool":
            values.append(rng.random() < 0.5)
        elif sig.kind == "flag":
            values.append(rng.getrandbits(32))
        else:
            values.append(rng.choice(list(sig.enum)))
    return cls(node, *values)


def _vec(rng: random.Random, n: int, low: float = -10.0, high: float = 10.0) -> list[float]:
    return [rng.uniform(low, high) for _ in range(n)]


def _tok(rng: random.Random) -> str:
    return "a" + "".join(rng.choice("abcxyz019-_") for _ in range(rng.randint(0, 10))) + "b"


def random_message(rng: random.Random) -> Any:
    """A random valid message of the project's dimensions (n = 3, three wheels, θ of 3)."""
    n = ROBOT_DIMS.dof
    kind = rng.choice(MESSAGE_TYPES)
    common = {"seq": rng.getrandbits(64), "time": rng.uniform(0, 1e6)}
    if kind.KIND == "operator_command":
        return kind(operator_id=_tok(rng), session_id=_tok(rng), seq=common["seq"], send_time=common["time"],
                    joystick=_vec(rng, n, -1, 1), q_d=_vec(rng, n), qd_d=_vec(rng, n), qdd_d=_vec(rng, n),
                    deadman=rng.random() < 0.5, estop=rng.random() < 0.1,
                    control_request=rng.choice(list(ControlRequest)))
    if kind.KIND == "robot_state":
        groups = [rng.choice(list(SetClass)) for _ in range(rng.randint(0, 4))]
        k_h = rng.random()
        return kind(**common, q=_vec(rng, n), qd_hat=_vec(rng, n), q_ref=_vec(rng, n), group_classes=groups,
                    active_group=rng.randrange(len(groups)) if groups else None,
                    authority=rng.choice(list(Authority)), k_s=float(rng.random() < 0.5), k_h=k_h, k_f=1 - k_h,
                    u_h=_vec(rng, n), u_f=_vec(rng, n), u_s=_vec(rng, n),
                    wheel_torques=_vec(rng, ROBOT_DIMS.n_wheels), theta_hat=_vec(rng, ROBOT_DIMS.n_theta),
                    min_margin=rng.uniform(-1, 1), region_margins=_vec(rng, rng.randint(0, 6)),
                    estop_active=rng.random() < 0.1, lease_holder=rng.choice((None, _tok(rng))),
                    link=LinkHealth(rng.uniform(0, 500), rng.random(), rng.uniform(0, 1e3), rng.uniform(0, 1e3)),
                    lease_since=rng.choice((None, rng.uniform(0, 1e6))))
    if kind.KIND == "event":
        return kind(**common, kind=rng.choice(list(EventKind)), severity=rng.choice(list(Severity)),
                    source=_tok(rng), text="é✓ text\n"[: rng.randint(0, 8)] * rng.randint(0, 30))
    if kind.KIND == "heartbeat":
        return kind(role=_tok(rng), id=_tok(rng), **common)
    if kind.KIND == "lease_request":
        return kind(operator_id=_tok(rng), session_id=_tok(rng), **common, action=rng.choice(list(LeaseAction)))
    if kind.KIND == "lease_reply":
        return kind(request_seq=common["seq"], time=common["time"], granted=rng.random() < 0.5,
                    holder=rng.choice((None, _tok(rng))), reason="busy" * rng.randint(0, 10))
    return kind(**common, q=_vec(rng, n), qd=_vec(rng, n))


# --- mutations -------------------------------------------------------------------------------------

_SPECIAL_FLOATS = (math.nan, math.inf, -math.inf, 1e308, -0.0, 5e-324)
_JUNK_VALUES: tuple[Any, ...] = (None, True, 0, -1, 2**64 - 1, 1.5, math.nan, "", "x" * 300, b"\x00", [],
                                 [1.0] * 2, [1.0] * 4, [math.inf] * 3, {}, {"a": 1}, "safe", "human")


def mutate_bytes(rng: random.Random, data: bytes) -> bytes:
    """One random byte-level mutation (flip, set, insert, delete, truncate, splice, repeat)."""
    buf = bytearray(data)
    op = rng.randrange(7)
    if op == 0 and buf:
        i = rng.randrange(len(buf))
        buf[i] ^= 1 << rng.randrange(8)
    elif op == 1 and buf:
        buf[rng.randrange(len(buf))] = rng.choice((0x00, 0xFF, 0x7F, 0x80, 0xC1, 0xCB, 0xD9, 0xDD, 0xDF,
                                                   rng.randrange(256)))
    elif op == 2:
        i = rng.randrange(len(buf) + 1)
        buf[i:i] = rng.randbytes(rng.randint(1, 8))
    elif op == 3 and buf:
        i = rng.randrange(len(buf))
        del buf[i:i + rng.randint(1, 8)]
    elif op == 4:
        del buf[rng.randrange(len(buf) + 1):]
    elif op == 5 and buf:
        i, j = sorted(rng.randrange(len(buf) + 1) for _ in range(2))
        buf[i:j] = buf[j:] + buf[:i]
    else:
        buf += buf[: rng.randrange(len(buf) + 1)]
    return bytes(buf)


def mutate_map(rng: random.Random, body: dict[str, Any]) -> dict[str, Any]:
    """One structure-aware mutation of a message map (drop, add, replace, resize, re-version)."""
    body = dict(body)
    keys = list(body)
    op = rng.randrange(6)
    key = rng.choice(keys)
    if op == 0:
        del body[key]
    elif op == 1:
        body[rng.choice(("extra", "zz", key + "_x"))] = rng.choice(_JUNK_VALUES)
    elif op == 2:
        body[key] = rng.choice(_JUNK_VALUES)
    elif op == 3 and isinstance(body[key], list) and body[key]:
        items = list(body[key])
        if rng.random() < 0.5:
            items.append(items[0])
        else:
            items[rng.randrange(len(items))] = rng.choice(_SPECIAL_FLOATS)
        body[key] = items
    elif op == 4:
        body["version"] = [rng.choice((0, 1, 2, 255)), rng.choice((0, 1, 9))]
    else:
        body[key] = rng.choice(_SPECIAL_FLOATS)
    return body


# --- campaigns -----------------------------------------------------------------------------------------

def can_inputs(rng: random.Random, count: int) -> Iterator[tuple[int, bytes, bool, int | None]]:
    """Raw frame fields: random ids/lengths/RTR, and mutations of valid frames."""
    for _ in range(count):
        r = rng.random()
        if r < 0.4:
            is_remote = rng.random() < 0.2
            length = rng.randint(0, 9)
            arb = rng.randrange(0x800) if rng.random() < 0.95 else rng.choice((-1, 0x800, 2**29, 2**40))
            yield arb, b"" if is_remote else rng.randbytes(length), is_remote, length if is_remote else None
            continue
        frame = cs.encode(random_can_message(rng))
        arb, data, remote, dlc = frame.arbitration_id, frame.data, frame.is_remote, frame.dlc
        if r < 0.6:
            data = mutate_bytes(rng, data)
            dlc = None if not remote else dlc
            if remote and data:
                remote = rng.random() < 0.5
        elif r < 0.7:
            arb ^= 1 << rng.randrange(11)
        elif r < 0.8:
            remote = not remote
            data, dlc = (b"", rng.randint(0, 8)) if remote else (data, None)
        elif r < 0.9 and len(data) >= 4:  # plant a special float32 bit pattern
            i = rng.randrange(0, len(data) - 3)
            special = struct.pack("<f", rng.choice((math.nan, math.inf, -math.inf, 1e-45)))
            data = data[:i] + special + data[i + 4:]
        yield arb, data, remote, dlc


def message_inputs(rng: random.Random, count: int) -> Iterator[bytes]:
    """Payloads: random bytes, byte-mutated and structure-mutated valid messages."""
    corpus = [random_message(rng) for _ in range(64)]
    encoded = [encode_message(m) for m in corpus]
    maps = [to_map(m) for m in corpus]
    for _ in range(count):
        r = rng.random()
        if r < 0.25:
            yield rng.randbytes(rng.choice((0, 1, 2, 8, 64, rng.randint(0, 7000))))
        elif r < 0.3:  # a map header claiming far more entries than there are bytes
            yield rng.choice((b"\xdf\xff\xff\xff\xff", b"\xdd\x7f\xff\xff\xff", b"\xdb\xff\xff\xff\xff")) \
                + rng.randbytes(rng.randint(0, 16))
        elif r < 0.7:
            data = rng.choice(encoded)
            for _ in range(rng.randint(1, 4)):
                data = mutate_bytes(rng, data)
            yield data
        else:
            body = rng.choice(maps)
            for _ in range(rng.randint(1, 3)):
                body = mutate_map(rng, body)
            yield msgpack.packb(body, use_bin_type=True)


def key_inputs(rng: random.Random, count: int) -> Iterator[str]:
    """Key strings: valid keys mutated character-wise, and random strings."""
    alphabet = "ab01-_/*$#?. \x00é" + "sharedctlv1"
    for _ in range(count):
        tail = rng.choice(list(KINDS.values()))
        key = "/".join((PREFIX, _tok(rng), *(_tok(rng) if t == "<role>" else t for t in tail)))
        chars = list(key)
        for _ in range(rng.randint(0, 3)):
            i = rng.randrange(len(chars) + 1)
            if rng.random() < 0.5 and i < len(chars):
                del chars[i]
            else:
                chars.insert(i, rng.choice(alphabet))
        yield "".join(chars) if rng.random() < 0.9 else "".join(rng.choice(alphabet) for _ in range(rng.randint(0, 40)))


def is_valid_attachment_output(decoded: Any) -> bool:
    return (isinstance(decoded, Signature) and TOKEN_PATTERN.fullmatch(decoded.signer) is not None
            and isinstance(decoded.value, bytes) and len(decoded.value) == SIGNATURE_LEN)


def attachment_inputs(rng: random.Random, count: int) -> Iterator[bytes]:
    """Signature attachments: random bytes, byte-mutated valid ones, and maps with fields changed or missing."""
    corpus = [encode_attachment(_tok(rng), rng.randbytes(SIGNATURE_LEN)) for _ in range(32)]
    junk = (None, 0, -1, 2, 1.5, "", "a/b", "x" * 70, b"\x00" * 63, b"\x00" * 65, [], {}, True)
    for _ in range(count):
        r = rng.random()
        if r < 0.2:
            yield rng.randbytes(rng.choice((0, 1, 8, 64, 96, rng.randint(0, 600))))
        elif r < 0.6:
            data = rng.choice(corpus)
            for _ in range(rng.randint(1, 3)):
                data = mutate_bytes(rng, data)
            yield data
        else:
            body = msgpack.unpackb(rng.choice(corpus), raw=False)
            for _ in range(rng.randint(0, 2)):
                field_name = rng.choice(("v", "signer", "sig", "extra"))
                if rng.random() < 0.3:
                    body.pop(field_name, None)
                else:
                    body[field_name] = rng.choice(junk)
            yield msgpack.packb(body, use_bin_type=True)


def fuzz_inputs(name: str, inputs: Iterator[Any], decode: Callable[[Any], Any],
                valid: Callable[[Any], bool], report: FuzzReport) -> FuzzReport:
    """Feed ``inputs`` to ``decode``; count typed errors, valid results and escapes into ``report``."""
    for item in inputs:
        report.inputs += 1
        try:
            decoded = decode(item)
        except ProtocolError as exc:
            report.typed_errors += 1
            report.errors[type(exc).__name__] += 1
            continue
        except Exception as exc:  # noqa: BLE001 — an escape is exactly what the campaign looks for
            report.escapes += 1
            if len(report.examples) < 5:
                report.examples.append(f"{name}: {type(exc).__name__}: {exc!s:.120} on {item!r:.200}")
            continue
        if valid(decoded):
            report.accepted += 1
        else:
            report.escapes += 1
            if len(report.examples) < 5:
                report.examples.append(f"{name}: invalid value {decoded!r:.200} from {item!r:.200}")
    return report


def run_campaign(decoder: str, count: int, seed: int = 0) -> FuzzReport:
    """Fuzz one decoder (``can``, ``message``, ``key`` or ``attachment``) with ``count`` inputs."""
    rng = random.Random(f"{decoder}:{seed}")
    report = FuzzReport(decoder)
    if decoder == "can":
        return fuzz_inputs(decoder, can_inputs(rng, count),
                           lambda f: cs.decode(f[0], f[1], f[2], dlc=f[3]), is_valid_can_output, report)
    if decoder == "message":
        return fuzz_inputs(decoder, message_inputs(rng, count), decode_message, is_valid_message_output, report)
    if decoder == "key":
        return fuzz_inputs(decoder, key_inputs(rng, count), parse_key, is_valid_key_output, report)
    if decoder == "attachment":
        return fuzz_inputs(decoder, attachment_inputs(rng, count), decode_attachment, is_valid_attachment_output,
                           report)
    raise ValueError(f"unknown decoder {decoder!r}; choose from {', '.join(DECODERS)}")

