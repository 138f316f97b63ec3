"""CAN bus load from the frames actually sent, with worst-case bit stuffing (pure).

A classic CAN 2.0A data frame with an 11-bit identifier and n data bytes has 34 + 8n bits from
start-of-frame to the end of the CRC (SOF 1, identifier 11, RTR 1, IDE 1, r0 1, DLC 4, data 8n,
CRC 15), all subject to bit stuffing, then 13 bits that are not (CRC delimiter 1, ACK 2, EOF 7,
interframe space 3). In the worst case one stuff bit follows every four bits after the first, so

    bits(n) = 34 + 8n + 13 + ⌊(34 + 8n − 1) / 4⌋      (Davis, Burns, Bril, Lukkien 2007, eq. (2))

135 bits for 8 bytes, 95 for 4, 55 for none. A remote (RTR) frame carries no data field whatever
its DLC says, so it counts as n = 0. 29-bit identifiers (CAN 2.0B) have 54 stuffable bits.
"""
from __future__ import annotations

from collections.abc import Iterable

STUFFED_HEADER_BITS = {False: 34, True: 54}   # is_extended_id → stuffable bits before the data
UNSTUFFED_TAIL_BITS = 13
BITRATE = 1_000_000


def frame_bits(dlc: int, is_remote: bool = False, is_extended: bool = False) -> int:
    """Worst-case length on the wire, in bits, of one classic CAN frame (interframe space included)."""
    if not 0 <= dlc <= 8:
        raise ValueError(f"classic CAN frames carry 0..8 data bytes, got dlc={dlc}")
    data = 0 if is_remote else 8 * dlc
    stuffable = STUFFED_HEADER_BITS[bool(is_extended)] + data
    return stuffable + UNSTUFFED_TAIL_BITS + (stuffable - 1) // 4


def bus_load(frames: Iterable[tuple[int, bool, bool]], seconds: float, bitrate: int = BITRATE) -> float:
    """Fraction of `bitrate` taken by `frames` ((dlc, is_remote, is_extended) each) over `seconds`."""
    if seconds <= 0:
        raise ValueError("the observation window must be positive")
    return sum(frame_bits(*f) for f in frames) / (seconds * bitrate)
