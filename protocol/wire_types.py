"""Field validators, bounds and dimensions shared by the Zenoh message schemas.

A validator takes a Python value and the field name, and returns the canonical
value (floats as ``float``, arrays as ``tuple``, enums as members) or raises the
typed error. Message constructors and the decoder run the same validators, so a
message that exists is a message that may be sent.
"""
from __future__ import annotations

import enum
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .errors import NonFiniteValue, OutOfRange, WrongLength, WrongType

MAX_DOF = 8
MAX_THETA = 16
MAX_WHEELS = 8
MAX_GROUPS = 16
MAX_REGIONS = 32
MAX_TOKEN_LEN = 64
MAX_TEXT_LEN = 256
MAX_UINT64 = 2**64 - 1

TOKEN_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,%d}" % (MAX_TOKEN_LEN - 1))
_FORBIDDEN_TEXT = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f\ud800-\udfff]")  # C0/C1 but \t \n; surrogates

Check = Callable[[Any, str], Any]


@dataclass(frozen=True, slots=True)
class Dims:
    """Array lengths a peer expects: degrees of freedom, parameters θ̂, wheels."""

    dof: int = 3
    n_theta: int = 3
    n_wheels: int = 3

    def __post_init__(self) -> None:
        for name, low, high in (("dof", 1, MAX_DOF), ("n_theta", 0, MAX_THETA), ("n_wheels", 1, MAX_WHEELS)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise WrongType(f"{name} must be an int")
            if not low <= value <= high:
                raise OutOfRange(f"{name} {value} outside {low}..{high}")


ROBOT_DIMS = Dims(dof=3, n_theta=3, n_wheels=3)
"""This project's robot: planar base (x, y, yaw), three wheels, three parameters."""


def check_token(value: Any, what: str, error: type[Exception] = OutOfRange) -> str:
    """An identifier: ASCII letters, digits, ``_`` and ``-``; 1..64 chars, not starting with ``_``/``-``."""
    if not isinstance(value, str):
        raise WrongType(f"{what} must be a string")
    if len(value) > MAX_TOKEN_LEN or TOKEN_PATTERN.fullmatch(value) is None:
        raise error(f"{what} must match {TOKEN_PATTERN.pattern}")
    return value


def real(low: float = -math.inf, high: float = math.inf) -> Check:
    """A finite real number in ``[low, high]``; ints are accepted and become floats."""

    def check(value: Any, what: str) -> float:
        if type(value) is not float:
            if isinstance(value, bool) or not hasattr(value, "__float__"):
                raise WrongType(f"{what} must be a number")
            try:
                value = float(value)
            except OverflowError:
                raise OutOfRange(f"{what} exceeds the float range") from None
            except (TypeError, ValueError):
                raise WrongType(f"{what} must be a number") from None
        if not math.isfinite(value):
            raise NonFiniteValue(f"{what} is not finite")
        if not low <= value <= high:
            raise OutOfRange(f"{what} {value} outside [{low}, {high}]")
        return value

    return check


def uint64(value: Any, what: str) -> int:
    """An unsigned 64-bit integer."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise WrongType(f"{what} must be an unsigned integer")
    if not 0 <= value <= MAX_UINT64:
        raise OutOfRange(f"{what} outside 0..2**64-1")
    return int(value)


def boolean(value: Any, what: str) -> bool:
    """``True`` or ``False`` (integers are not booleans on this wire)."""
    if not isinstance(value, bool):
        raise WrongType(f"{what} must be a bool")
    return value


def token(value: Any, what: str) -> str:
    """An identifier (see :func:`check_token`)."""
    return check_token(value, what)


def optional(check: Check) -> Check:
    """``None`` (MessagePack nil) or a value accepted by ``check``."""

    def check_optional(value: Any, what: str) -> Any:
        return None if value is None else check(value, what)

    return check_optional


def text(max_len: int = MAX_TEXT_LEN) -> Check:
    """Text of at most ``max_len`` characters; no control characters (but tab, newline), valid UTF-8."""

    def check(value: Any, what: str) -> str:
        if not isinstance(value, str):
            raise WrongType(f"{what} must be a string")
        if len(value) > max_len:
            raise WrongLength(f"{what} longer than {max_len} characters")
        if _FORBIDDEN_TEXT.search(value):
            raise OutOfRange(f"{what} contains control characters or lone surrogates")
        return value

    return check


def choice(enum_cls: type[enum.Enum]) -> Check:
    """A member of a string enum; on the wire its value (``"safe"``, ``"human"``, ...)."""

    def check(value: Any, what: str) -> enum.Enum:
        if isinstance(value, enum_cls):
            return value
        if not isinstance(value, str):
            raise WrongType(f"{what} must be a {enum_cls.__name__} string")
        try:
            return enum_cls(value)
        except ValueError:
            raise OutOfRange(f"{what} {value[:32]!r} is not a {enum_cls.__name__}") from None

    return check


def index(value: Any, what: str) -> int:
    """A non-negative int (array index)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise WrongType(f"{what} must be an int")
    if not 0 <= value < 2**31:
        raise OutOfRange(f"{what} {value} is not an index")
    return int(value)


def _as_sequence(value: Any, what: str) -> list | tuple:
    if isinstance(value, (list, tuple)):
        return value
    if getattr(value, "ndim", None) == 1 and hasattr(value, "tolist"):  # numpy 1-D arrays
        return value.tolist()
    raise WrongType(f"{what} must be an array")


def sequence(item: Check, max_len: int) -> Check:
    """An array of at most ``max_len`` items, each accepted by ``item``; returns a tuple."""

    def check(value: Any, what: str) -> tuple:
        items = _as_sequence(value, what)
        if len(items) > max_len:
            raise WrongLength(f"{what} has {len(items)} items, at most {max_len} allowed")
        return tuple(item(x, what) for x in items)

    return check


def vector(low: float = -math.inf, high: float = math.inf, max_len: int = MAX_DOF) -> Check:
    """An array of finite floats (length is checked against the message's dimensions)."""
    return sequence(real(low, high), max_len)
