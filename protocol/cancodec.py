"""One frame kind's data bytes, compiled once from its signal table: a :class:`FrameCodec`.

cantools compiles each message of a database into a codec once and every caller encodes and
decodes through it; here :class:`FrameCodec` does the same for one CANSimple frame kind
(:class:`~.canspec.FrameSpec`): its signals become one little-endian `struct.Struct` — a field per
signal at its start byte (``f`` for a float32, the narrowest of ``B``/``H``/``I``/``Q`` for
``length`` bits), pad bytes between the fields and up to the DLC — and each signal keeps its own
check (:meth:`~.canspec.SignalSpec.to_field`, :meth:`~.canspec.SignalSpec.from_field`). Packing is
one ``pack`` call after the checks (pad bytes and bits beyond a signal's length are written as
zero); unpacking is one ``unpack`` call, then the checks, which raise the typed errors of
:mod:`.errors` (NaN/inf → :class:`NonFiniteValue`, a value beyond its bounds → :class:`OutOfRange`).

Every signal of the CANSimple table starts on a byte boundary, in ascending order without
overlap; a table that does not is refused when it is compiled (:class:`ValueError`, at import
of :mod:`.cansimple`), never mis-packed.
"""
from __future__ import annotations

import struct
from operator import attrgetter

from .canspec import FrameSpec
from .errors import BadLength, WrongLength

_CODE_BITS = {"f": 32, "B": 8, "H": 16, "I": 32, "Q": 64}


def struct_format(spec: FrameSpec) -> str:
    """The little-endian `struct` format of a frame kind's data bytes (``ValueError`` if the signals
    do not start on byte boundaries, overlap, are out of order or overrun the DLC)."""
    parts, offset = ["<"], 0
    for sig in spec.signals:
        code = sig.struct_code
        if sig.start % 8 or sig.start // 8 < offset or (code == "f" and sig.length != 32):
            raise ValueError(f"{spec.name}.{sig.name}: start bit {sig.start}, length {sig.length} "
                             f"cannot be compiled to a struct field")
        if sig.start // 8 > offset:
            parts.append(f"{sig.start // 8 - offset}x")
        parts.append(code)
        offset = sig.start // 8 + _CODE_BITS[code] // 8
    if offset > spec.dlc:
        raise ValueError(f"{spec.name}: the signals need {offset} bytes, the DLC is {spec.dlc}")
    if spec.dlc > offset:
        parts.append(f"{spec.dlc - offset}x")
    return "".join(parts)


class FrameCodec:
    """The data bytes of one frame kind <-> its signal values, in the order of the table."""

    __slots__ = ("spec", "layout", "values_of", "_to_fields", "_from_fields")

    def __init__(self, spec: FrameSpec) -> None:
        self.spec = spec
        self.layout = struct.Struct(struct_format(spec))
        attrs = [sig.attr for sig in spec.signals]
        #: the signal values of a typed frame, as a tuple in table order
        self.values_of = (attrgetter(*attrs) if len(attrs) > 1
                          else (lambda frame, a=attrs[0]: (getattr(frame, a),)) if attrs
                          else (lambda frame: ()))
        self._to_fields = tuple(sig.to_field for sig in spec.signals)
        self._from_fields = tuple(sig.from_field for sig in spec.signals)

    def pack(self, values) -> bytes:
        """The DLC data bytes of the signal values (each validated as the typed frame's constructor does)."""
        if len(values) != len(self._to_fields):
            raise WrongLength(f"{self.spec.name} has {len(self._to_fields)} signals, got {len(values)} values")
        return self.layout.pack(*[to_field(v) for to_field, v in zip(self._to_fields, values)])

    def unpack(self, data) -> tuple:
        """The canonical signal values of data bytes of exactly the DLC (the typed error otherwise)."""
        try:
            fields = self.layout.unpack(data)
        except struct.error:
            raise BadLength(f"{self.spec.name} has DLC {self.spec.dlc}, got {len(data)} bytes") from None
        return tuple([from_field(f) for from_field, f in zip(self._from_fields, fields)])
