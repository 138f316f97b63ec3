"""The two CANSimple frames of every control period, read and written by their layout.

At 500 Hz the controller sends three Set_Input_Torque frames and, on udp_multicast, receives them
back along with the drives' three Get_Encoder_Estimates: ~3,000 frames/s through the general codec
(`cansimple.encode`/`decode`: a validated dataclass per frame, a loop over the signal table) cost
tens of microseconds per period on the loop thread. This module handles exactly those frames from
the layout the codec's table gives them (`cansimple.FRAME_SPECS`, checked when it is imported):

* Set_Input_Torque (0x0E, host → drive, DLC 8): Input_Torque float32 little-endian at byte 0,
  bytes 4–7 zero (`torque_data`; a non-finite or out-of-range torque raises the codec's typed
  error, `canspec.to_float32`);
* Get_Encoder_Estimates (0x09, drive → host, DLC 8): Pos_Estimate, Vel_Estimate float32 at bytes
  0 and 4 (`encoder_values`).

`classify` looks at the arbitration id, the DLC and the bytes of a standard-id data frame of a
configured node and answers ECHO (a well-formed Set_Input_Torque: our own frame coming back, never
acted on), ENCODER (a well-formed estimate with finite values) or None — everything else, including
every frame the codec would refuse, goes to the codec, which decodes it or counts it as bad.
"""
from __future__ import annotations

import math
import struct

from sharedctl.protocol import cansimple as cs
from sharedctl.protocol.canframe import arbitration_id
from sharedctl.protocol.canspec import to_float32
from sharedctl.protocol.odrive_enums import CommandId

ECHO = "echo"
ENCODER = "encoder"

_TORQUE = int(CommandId.SET_INPUT_TORQUE)
_ENCODER = int(CommandId.GET_ENCODER_ESTIMATES)
_DLC = 8
_F32 = struct.Struct("<f")
_F32_PAIR = struct.Struct("<ff")
_TORQUE_PADDING = bytes(_DLC - 4)


def _layout(cls) -> tuple[int, tuple[tuple[int, int, str], ...]]:
    spec = cs.FRAME_SPECS[cls]
    return spec.dlc, tuple((sig.start, sig.length, sig.kind) for sig in spec.signals)


# the layout this module assumes, against the codec's own table (an import error if the table changes)
if _layout(cs.SetInputTorque) != (_DLC, ((0, 32, "float"),)) or \
        _layout(cs.GetEncoderEstimates) != (_DLC, ((0, 32, "float"), (32, 32, "float"))) or \
        cs.FRAME_SPECS[cs.SetInputTorque].cmd != _TORQUE or cs.FRAME_SPECS[cs.GetEncoderEstimates].cmd != _ENCODER:
    raise ImportError("frame_layout: the CANSimple table no longer matches the layout of the per-period frames")


def torque_id(node_id: int) -> int:
    """The arbitration id of Set_Input_Torque to `node_id`."""
    return arbitration_id(node_id, _TORQUE)


def torque_data(torque: float) -> bytes:
    """The 8 data bytes of Set_Input_Torque (as `cansimple.encode(SetInputTorque(n, torque)).data`)."""
    return _F32.pack(to_float32(torque, "input_torque")) + _TORQUE_PADDING


def classify(arb_id, dlc, data, nodes) -> str | None:
    """ECHO, ENCODER or None (→ the codec) for a standard-id data frame (the caller checks those two
    flags) addressed to or sent by one of `nodes`. Never raises: an odd field answers None."""
    if type(arb_id) is not int or type(dlc) is not int or dlc != _DLC or (arb_id >> 5) not in nodes:
        return None
    cmd = arb_id & 0x1F
    try:
        if len(data) != _DLC:
            return None
        if cmd == _ENCODER:
            pos, vel = _F32_PAIR.unpack(data)
            return ENCODER if math.isfinite(pos) and math.isfinite(vel) else None
        if cmd == _TORQUE:
            return ECHO if math.isfinite(_F32.unpack_from(data)[0]) else None
    except (TypeError, struct.error):
        return None
    return None


def encoder_values(data) -> tuple[float, float]:
    """(pos_estimate turns, vel_estimate turns/s) of a frame `classify` called ENCODER."""
    return _F32_PAIR.unpack(data)
