"""Any python-can bus as a :class:`Transport`, through its public `recv`/`send` (SocketCAN, vcan, …).

Each frame is a `can.Message` both ways — python-can's own cost; SocketCAN does not echo a socket's
own frames, so a node there reads only what the others send. python-can reports a frame it cannot
read and a failing interface alike as `can.CanError`; both count as unreadable in `read`, which
stops after `limit` arrivals either way.
"""
from __future__ import annotations

import time

import can

from .base import Frame, Transport, UnreadableFrame


def message(arbitration_id: int, is_remote: bool, dlc: int, data: bytes) -> can.Message:
    """The `can.Message` of a classic standard-id frame."""
    return can.Message(arbitration_id=arbitration_id, is_extended_id=False, is_remote_frame=is_remote, dlc=dlc,
                       data=None if is_remote else data)


class PythonCanTransport(Transport):
    """`bus`, any object with python-can's `recv(timeout)` and `send(msg, timeout)` (and `fileno`,
    `shutdown` where used)."""

    UNREADABLE = (UnreadableFrame, can.CanError)

    def __init__(self, bus) -> None:
        self.bus = bus
        self.bad = 0

    def fileno(self) -> int:
        return self.bus.fileno()

    def shutdown(self) -> None:
        self.bus.shutdown()

    def recv(self, timeout: float | None) -> Frame | None:
        """One frame, waiting up to `timeout` s; None if none came. The bus's errors propagate."""
        msg = self.bus.recv(timeout=timeout)
        if msg is None:
            return None
        return Frame(msg.arbitration_id, msg.is_remote_frame, msg.is_extended_id, msg.is_error_frame,
                     msg.dlc, bytes(msg.data), msg.timestamp or time.time(), msg)

    def forward(self, frame: Frame) -> None:
        self.bus.send(frame.raw)

    def send(self, arbitration_id: int, is_remote: bool, dlc: int, data: bytes, timeout: float | None = None) -> None:
        self.bus.send(message(arbitration_id, is_remote, dlc, data), timeout=timeout)
