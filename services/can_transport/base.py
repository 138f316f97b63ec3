"""What every CAN transport is: :class:`Transport` (send, recv, fileno, shutdown) and the :class:`Frame` it reads.

The shape of python-can's `BusABC`: one small abstract class, each back-end a plug-in file of this
package, opened by services/can_bus.py. A transport reads frames as plain tuples — no per-frame
object beyond the tuple — and sends them from their fields, so the loops that run every period
pay for the system call and little else.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import NamedTuple


class Frame(NamedTuple):
    """One received classic CAN frame."""

    arbitration_id: int
    is_remote: bool
    is_extended: bool
    is_error: bool
    dlc: int
    data: bytes
    arrival: float          # s, the interface's receive time, time.time() scale
    raw: object             # what `forward` resends as is (the datagram, the can.Message)


class UnreadableFrame(ValueError):
    """Something arrived that is not a classic CAN frame the transport can read; it has been consumed."""


class Transport(ABC):
    """A CAN bus as the processes use it. `read` and `forward` are built on the four abstract methods."""

    #: what `recv` raises for something it received but cannot read (consumed; `read` counts it in `bad`)
    UNREADABLE: tuple[type[BaseException], ...] = (UnreadableFrame,)
    bad: int = 0                # unreadable arrivals `read` has skipped

    @abstractmethod
    def send(self, arbitration_id: int, is_remote: bool, dlc: int, data: bytes, timeout: float | None = None) -> None:
        """Send one classic standard-id frame (`data` empty for a remote frame, whose length is `dlc`)."""

    @abstractmethod
    def recv(self, timeout: float | None) -> Frame | None:
        """One frame, waiting up to `timeout` s (None: until one comes); None if none came in time.
        Raises one of `UNREADABLE` for an arrival it cannot read (the next call reads on)."""

    @abstractmethod
    def fileno(self) -> int:
        """A descriptor that is readable when a frame is waiting (for `select`)."""

    @abstractmethod
    def shutdown(self) -> None:
        """Release the bus; safe to call twice."""

    def read(self, limit: int) -> list[Frame]:
        """The frames waiting now, without waiting: up to `limit` arrivals, unreadable ones counted in `bad`."""
        out: list[Frame] = []
        for _ in range(limit):
            try:
                frame = self.recv(0.0)
            except self.UNREADABLE:
                self.bad += 1
                continue
            if frame is None:
                break
            out.append(frame)
        return out

    def forward(self, frame: Frame) -> None:
        """Send a received frame on unchanged."""
        self.send(frame.arbitration_id, frame.is_remote, frame.dlc, frame.data)

    def __enter__(self) -> Transport:
        return self

    def __exit__(self, *exc) -> None:
        self.shutdown()
