"""A raw classic-CAN frame and the CANSimple arbitration-id layout.

CANSimple uses 11-bit standard ids: ``arbitration_id = node_id << 5 | cmd_id``
(upper 6 bits node 0..63, lower 5 bits command 0..31).
"""
from __future__ import annotations

from dataclasses import dataclass

from .errors import BadArbitrationId, BadLength, BadNodeId, WrongType

MAX_NODE_ID = 0x3F
MAX_CMD_ID = 0x1F
MAX_STANDARD_ID = 0x7FF
MAX_DLC = 8
DEFAULT_WHEEL_NODES: tuple[int, int, int] = (0, 1, 2)


def check_node_id(node_id: object) -> int:
    """Return ``node_id`` if it is an int in 0..63, else raise :class:`BadNodeId`."""
    if type(node_id) is not int:
        if isinstance(node_id, bool) or not isinstance(node_id, int):
            raise BadNodeId(f"node id must be an int, got {type(node_id).__name__}")
        node_id = int(node_id)
    if not 0 <= node_id <= MAX_NODE_ID:
        raise BadNodeId(f"node id {node_id} outside 0..{MAX_NODE_ID}")
    return node_id


def arbitration_id(node_id: int, cmd_id: int) -> int:
    """Compose an 11-bit CANSimple id from a node id (0..63) and a command id (0..31)."""
    node_id = check_node_id(node_id)
    if type(cmd_id) is bool or not isinstance(cmd_id, int) or not 0 <= cmd_id <= MAX_CMD_ID:
        raise BadArbitrationId(f"command id {cmd_id!r} outside 0..{MAX_CMD_ID}")
    return (node_id << 5) | int(cmd_id)


def split_arbitration_id(arb_id: int) -> tuple[int, int]:
    """Split an 11-bit CANSimple id into ``(node_id, cmd_id)``."""
    if type(arb_id) is bool or not isinstance(arb_id, int) or not 0 <= arb_id <= MAX_STANDARD_ID:
        raise BadArbitrationId(f"arbitration id {arb_id!r} is not an 11-bit standard id")
    return arb_id >> 5, arb_id & MAX_CMD_ID


@dataclass(frozen=True, slots=True)
class CanFrame:
    """One classic CAN frame as the codec sees it.

    ``dlc`` is the length field of the frame: for data frames it equals
    ``len(data)`` (pass ``None`` to take it from ``data``); for remote (RTR)
    frames ``data`` is empty and ``dlc`` is the requested length (python-can's
    ``Message`` follows the same convention). ``is_extended_id`` frames are
    representable so that a caller can hand over anything it received; the
    CANSimple decoder rejects them.
    """

    arbitration_id: int
    data: bytes = b""
    is_remote: bool = False
    dlc: int | None = None
    is_extended_id: bool = False

    def __post_init__(self) -> None:
        if type(self.arbitration_id) is bool or not isinstance(self.arbitration_id, int):
            raise WrongType("arbitration_id must be an int")
        if self.arbitration_id < 0 or self.arbitration_id > 0x1FFFFFFF:
            raise BadArbitrationId(f"arbitration id {self.arbitration_id} is not a CAN id")
        if not isinstance(self.data, (bytes, bytearray, memoryview)):
            raise WrongType("data must be bytes")
        if not isinstance(self.is_remote, bool) or not isinstance(self.is_extended_id, bool):
            raise WrongType("is_remote and is_extended_id must be bool")
        data = bytes(self.data)
        if len(data) > MAX_DLC:
            raise BadLength(f"classic CAN carries at most {MAX_DLC} bytes, got {len(data)}")
        dlc = self.dlc
        if dlc is not None and (type(dlc) is bool or not isinstance(dlc, int)):
            raise WrongType("dlc must be an int or None")
        if self.is_remote:
            if data:
                raise BadLength("a remote frame carries no data")
            dlc = 0 if dlc is None else dlc
            if not 0 <= dlc <= MAX_DLC:
                raise BadLength(f"remote frame DLC {dlc} outside 0..{MAX_DLC}")
        elif dlc is None:
            dlc = len(data)
        elif dlc != len(data):
            raise BadLength(f"DLC {dlc} does not match {len(data)} data bytes")
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "dlc", dlc)

    @property
    def node_id(self) -> int:
        """CANSimple node id (upper 6 bits of a standard id)."""
        return split_arbitration_id(self.arbitration_id)[0]

    @property
    def cmd_id(self) -> int:
        """CANSimple command id (lower 5 bits of a standard id)."""
        return split_arbitration_id(self.arbitration_id)[1]
