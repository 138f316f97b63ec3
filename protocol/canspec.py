"""Table types of the CANSimple codec: one :class:`FrameSpec` per command, one :class:`SignalSpec` per signal."""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Literal

from .errors import NonFiniteValue, OutOfRange, WrongType
from .odrive_enums import CommandId

_F32 = struct.Struct("<f")
SignalKind = Literal["float", "enum", "flag", "bool"]


def to_float32(value: object, what: str = "value", minimum: float | None = None) -> float:
    """Return ``value`` rounded to the nearest float32, refusing NaN/inf and overflow."""
    if type(value) is not float:
        if isinstance(value, bool) or not hasattr(value, "__float__"):
            raise WrongType(f"{what} must be a real number")
        try:
            value = float(value)  # ints, numpy scalars
        except OverflowError:
            raise OutOfRange(f"{what} exceeds the float range") from None
        except (TypeError, ValueError):
            raise WrongType(f"{what} must be a real number") from None
    if not math.isfinite(value):
        raise NonFiniteValue(f"{what} is not finite")
    try:
        value = _F32.unpack(_F32.pack(value))[0]
    except OverflowError:
        raise OutOfRange(f"{what} exceeds the float32 range") from None
    if minimum is not None and value < minimum:
        raise OutOfRange(f"{what} {value} is below {minimum}")
    return value


@dataclass(frozen=True, slots=True)
class SignalSpec:
    """One DBC signal: name, bit position, type, unit and the typed-frame attribute."""

    name: str
    attr: str
    start: int
    length: int
    kind: SignalKind
    unit: str = ""
    enum: type | None = None
    minimum: float | None = None

    @property
    def mask(self) -> int:
        return (1 << self.length) - 1

    def coerce(self, value: object) -> object:
        """Validate a Python value for this signal and return its canonical form."""
        if self.kind == "float":
            return to_float32(value, self.attr, self.minimum)
        if self.kind == "bool":
            if not isinstance(value, bool):
                raise WrongType(f"{self.attr} must be a bool")
            return value
        if isinstance(value, bool) or not isinstance(value, int):
            raise WrongType(f"{self.attr} must be an int or {self.enum.__name__}")
        if not 0 <= value <= self.mask:
            raise OutOfRange(f"{self.attr} {value} does not fit in {self.length} bits")
        try:
            return self.enum(value)
        except ValueError:
            raise OutOfRange(f"{self.attr} {value} is not a {self.enum.__name__}") from None

    def to_raw(self, value: object) -> int:
        """Bits of an already-coerced value."""
        if self.kind == "float":
            return int.from_bytes(_F32.pack(value), "little")
        return int(value)

    def from_raw(self, bits: int) -> object:
        """Canonical value of the raw bits (raises the typed error for invalid bits)."""
        if self.kind == "float":
            return to_float32(_F32.unpack(bits.to_bytes(4, "little"))[0], self.attr, self.minimum)
        if self.kind == "bool":
            if bits > 1:
                raise OutOfRange(f"{self.attr} {bits} is neither 0 nor 1")
            return bool(bits)
        return self.coerce(bits)


@dataclass(frozen=True, slots=True)
class FrameSpec:
    """One CANSimple command: DBC name (without ``AxisN_``), id, DLC, sender, signals."""

    cmd: CommandId
    name: str
    dlc: int
    sender: Literal["host", "odrive"]
    signals: tuple[SignalSpec, ...]
    comment: str

    @property
    def pollable(self) -> bool:
        """Get_* frames are sent by the ODrive and may be requested with RTR."""
        return self.sender == "odrive" and self.name.startswith("Get_")
