"""Frame I/O on a python-can bus, cheap where it runs every period: per transport.

A port reads frames as plain tuples ``Frame(arbitration_id, is_remote, is_extended, is_error,
dlc, data, arrival, raw)`` (``arrival``: the interface's receive time, ``time.time()`` scale)
and sends them.

* :class:`UdpMulticastPort` reads python-can's udp_multicast datagrams straight from the bus's
  socket (non-blocking ``recvmsg`` with the kernel timestamp python-can asked for, a ``select``
  only when it has to wait), looks only at the fields a CAN node needs, writes the datagram
  python-can would write for a frame (the same msgpack map, checked byte for byte by
  tests/services/test_can_ports.py), and forwards an unchanged frame by resending its datagram
  as is. Every node of a udp_multicast bus hears every frame, its own included; python-can's
  ``Bus.recv`` (a ``select`` and a full ``Message`` per frame) and ``Bus.send`` (a ``Message``,
  then a map built from it) cost 3–4 µs more per frame than this port on this machine
  (docs/performance.md), whose own cost is mostly the system call. The fault gateway forwards thousands of frames a
  second through it; the controller reads and writes its per-period frames through it.
* :class:`BusPort` is any other python-can bus (SocketCAN on vcan: the kernel does not echo a
  socket's own frames), through ``recv``/``send``.

The bus itself is still opened, configured (hop_limit=0) and shut down by services/can_bus.py.
"""
from __future__ import annotations

import select
import socket
import struct
import time
from typing import NamedTuple

import can
import msgpack


class Frame(NamedTuple):
    arbitration_id: int
    is_remote: bool
    is_extended: bool
    is_error: bool
    dlc: int
    data: bytes
    arrival: float          # s, time.time() scale
    raw: object             # what `forward` resends: the datagram or the can.Message


class UnreadableDatagram(ValueError):
    """A udp_multicast datagram that is not a classic CAN frame in python-can's format."""


def message(arbitration_id: int, is_remote: bool, dlc: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=arbitration_id, is_extended_id=False, is_remote_frame=is_remote, dlc=dlc,
                       data=None if is_remote else data)


class _Port:
    """What both ports share: `read`, the frames waiting now, on top of each one's `recv`."""

    UNREADABLE: type = Exception      # what `recv` raises for a frame it cannot read (counted in `bad`)
    bad: int

    def recv(self, timeout: float) -> Frame | None:
        raise NotImplementedError

    def read(self, limit: int) -> list[Frame]:
        """Up to `limit` frames that are waiting, without waiting; unreadable ones counted in `bad`."""
        out: list[Frame] = []
        while len(out) < limit:
            try:
                frame = self.recv(0.0)
            except self.UNREADABLE:
                self.bad += 1
                continue
            if frame is None:
                break
            out.append(frame)
        return out


class BusPort(_Port):
    """Any python-can bus."""

    UNREADABLE = can.CanError

    def __init__(self, bus) -> None:
        self.bus = bus
        self.bad = 0

    def fileno(self) -> int:
        return self.bus.fileno()

    def recv(self, timeout: float) -> Frame | None:
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


class UdpMulticastPort(_Port):
    """python-can udp_multicast, read and written on its socket directly (same datagram format).

    `send` is a `sendto` on the socket as python-can set it up (blocking: a UDP send waits only
    while the socket's send buffer is full); `timeout` is accepted for BusPort's signature."""

    UNREADABLE = UnreadableDatagram

    def __init__(self, bus) -> None:
        mc = bus._multicast
        self.bus, self.sock, self.destination = bus, mc._socket, mc._send_destination
        self.max_buffer = mc.max_buffer
        self.stamped = bool(getattr(mc, "timestamp_nanosecond", False))
        self.ancillary = mc.received_ancillary_buffer_size if self.stamped else 0
        self.timespec = struct.Struct(mc.received_timestamp_struct) if self.stamped else None
        self.bad = 0

    def fileno(self) -> int:
        return self.sock.fileno()

    def recv(self, timeout: float) -> Frame | None:
        """One frame, waiting up to `timeout` s; None if none came. A datagram that is not a frame
        raises UnreadableDatagram (after it has been consumed: the next call reads on)."""
        try:
            raw, ancillary, _, _ = self.sock.recvmsg(self.max_buffer, self.ancillary, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            if timeout <= 0.0 or not select.select([self.sock], [], [], timeout)[0]:
                return None
            try:
                raw, ancillary, _, _ = self.sock.recvmsg(self.max_buffer, self.ancillary, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                return None
        return self._frame(raw, ancillary)

    def _frame(self, raw: bytes, ancillary) -> Frame:
        arrival = time.time()
        if ancillary:
            seconds, nanoseconds = self.timespec.unpack(ancillary[0][2])
            arrival = seconds + nanoseconds * 1e-9
        try:
            d = msgpack.unpackb(raw, raw=False)
            if d.get("is_fd"):
                raise ValueError("CAN FD frame on a classic CAN bus")
            frame = Frame(d["arbitration_id"], d["is_remote_frame"], d["is_extended_id"], d["is_error_frame"],
                          d["dlc"], d["data"], arrival, raw)
        except (ValueError, KeyError, TypeError, AttributeError, msgpack.UnpackException) as exc:
            raise UnreadableDatagram(f"not a classic CAN frame: {type(exc).__name__}") from None
        if not (type(frame.arbitration_id) is int and type(frame.dlc) is int and type(frame.data) is bytes
                and type(frame.is_remote) is bool and type(frame.is_extended) is bool and type(frame.is_error) is bool):
            raise UnreadableDatagram("not a classic CAN frame: a field of the wrong type")
        return frame

    def forward(self, frame: Frame) -> None:
        self.sock.sendto(frame.raw, self.destination)

    def send(self, arbitration_id: int, is_remote: bool, dlc: int, data: bytes, timeout: float | None = None) -> None:
        self.sock.sendto(datagram(arbitration_id, is_remote, dlc, data), self.destination)


def datagram(arbitration_id: int, is_remote: bool, dlc: int, data: bytes) -> bytes:
    """The udp_multicast datagram of a classic standard-id frame: python-can's
    `pack_message(message(…))` (the map of every can.Message field, timestamp 0), without the Message."""
    return msgpack.packb({
        "timestamp": 0.0, "arbitration_id": arbitration_id, "is_extended_id": False, "is_remote_frame": is_remote,
        "is_error_frame": False, "channel": None, "dlc": dlc, "data": b"" if is_remote else bytes(data),
        "is_fd": False, "bitrate_switch": False, "error_state_indicator": False,
    }, use_bin_type=True)


def port_for(bus):
    """The fast port for a udp_multicast bus that exposes its socket as expected, else the generic one."""
    mc = getattr(bus, "_multicast", None)
    if mc is not None and all(hasattr(mc, a) for a in ("_socket", "_send_destination", "max_buffer",
                                                        "received_ancillary_buffer_size", "received_timestamp_struct")):
        return UdpMulticastPort(bus)
    return BusPort(bus)
