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
        if type(value) is self.enum and 0 <= value <= self.mask:
            return value                         # a member of the signal's enum, in its bits
        if isinstance(value, bool) or not isinstance(value, int):
            raise WrongType(f"{self.attr} must be an int or {self.enum.__name__}")
        if not 0 <= value <= self.mask:
            raise OutOfRange(f"{self.attr} {value} does not fit in {self.length} bits")
        try:
            return self.enum(value)
        except ValueError:
            raise OutOfRange(f"{self.attr} {value} is not a {self.enum.__name__}") from None

    @property
    def struct_code(self) -> str:
        """The little-endian `struct` field that carries this signal from its start byte: ``f`` for a
        float32, else the narrowest unsigned integer holding ``length`` bits (``B``, ``H``, ``I``, ``Q``)."""
        if self.kind == "float":
            return "f"
        return next(code for code, bits in (("B", 8), ("H", 16), ("I", 32), ("Q", 64)) if self.length <= bits)

    def to_field(self, value: object) -> object:
        """The `struct` field value of a Python value (validated and canonicalised by :meth:`coerce`)."""
        if self.kind == "float":
            return to_float32(value, self.attr, self.minimum)
        return int(self.coerce(value))

    def from_field(self, field: object) -> object:
        """Canonical value of an unpacked `struct` field; bits beyond ``length`` are ignored. Raises the
        typed error for invalid contents (NaN/inf, below ``minimum``, not an enum member, a bool above 1)."""
        if self.kind == "float":
            return to_float32(field, self.attr, self.minimum)
        bits = field & self.mask
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
