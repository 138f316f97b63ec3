"""Frame I/O for the CAN fault gateway: batch reads and cheap forwarding, per transport.

A port reads frames as plain tuples ``Frame(arbitration_id, is_remote, is_extended, is_error,
dlc, data, arrival, raw)`` (``arrival``: the interface's receive time, ``time.time()`` scale)
and sends them on.

* :class:`UdpMulticastPort` reads python-can's udp_multicast datagrams straight from the bus's
  socket (non-blocking ``recvmsg`` with the kernel timestamp python-can asked for), looks only at
  the fields the gateway needs, and forwards an unchanged frame by resending its datagram
  as is. Every node of a udp_multicast bus hears every frame, the gateway's own included; with
  python-can's ``Bus.recv`` (a ``select`` and a full ``Message`` per frame) the gateway spent
  35–70 µs per frame, which a babbling node at a few kHz turned into seconds of backlog.
* :class:`BusPort` is any other python-can bus (SocketCAN on vcan: the kernel does not echo a
  socket's own frames), through ``recv(0)``/``send``.

The bus itself is still opened, configured (hop_limit=0) and shut down by services/can_bus.py.
"""
from __future__ import annotations

import socket
import struct
import time
from typing import NamedTuple

import can
import msgpack
from can.interfaces.udp_multicast.utils import pack_message


class Frame(NamedTuple):
    arbitration_id: int
    is_remote: bool
    is_extended: bool
    is_error: bool
    dlc: int
    data: bytes
    arrival: float          # s, time.time() scale
    raw: object             # what `forward` resends: the datagram or the can.Message


def message(arbitration_id: int, is_remote: bool, dlc: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=arbitration_id, is_extended_id=False, is_remote_frame=is_remote, dlc=dlc,
                       data=None if is_remote else data)


class BusPort:
    """Any python-can bus."""

    def __init__(self, bus) -> None:
        self.bus = bus
        self.bad = 0

    def fileno(self) -> int:
        return self.bus.fileno()

    def read(self, limit: int) -> list[Frame]:
        out: list[Frame] = []
        while len(out) < limit:
            try:
                msg = self.bus.recv(0.0)
            except can.CanError:
                self.bad += 1
                continue
            if msg is None:
                break
            out.append(Frame(msg.arbitration_id, msg.is_remote_frame, msg.is_extended_id, msg.is_error_frame,
                             msg.dlc, bytes(msg.data), msg.timestamp or time.time(), msg))
        return out

    def forward(self, frame: Frame) -> None:
        self.bus.send(frame.raw)

    def send(self, arbitration_id: int, is_remote: bool, dlc: int, data: bytes) -> None:
        self.bus.send(message(arbitration_id, is_remote, dlc, data))


class UdpMulticastPort:
    """python-can udp_multicast, read and written on its socket directly (same datagram format)."""

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

    def read(self, limit: int) -> list[Frame]:
        out: list[Frame] = []
        while len(out) < limit:
            try:
                raw, ancillary, _, _ = self.sock.recvmsg(self.max_buffer, self.ancillary, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                break
            arrival = time.time()
            if ancillary:
                seconds, nanoseconds = self.timespec.unpack(ancillary[0][2])
                arrival = seconds + nanoseconds * 1e-9
            try:
                d = msgpack.unpackb(raw, raw=False)
                if d.get("is_fd"):
                    raise ValueError("CAN FD frame on a classic CAN bus")
                out.append(Frame(d["arbitration_id"], d["is_remote_frame"], d["is_extended_id"], d["is_error_frame"],
                                 d["dlc"], bytes(d["data"]), arrival, raw))
            except (ValueError, KeyError, TypeError, msgpack.UnpackException):
                self.bad += 1
        return out

    def forward(self, frame: Frame) -> None:
        self.sock.sendto(frame.raw, self.destination)

    def send(self, arbitration_id: int, is_remote: bool, dlc: int, data: bytes) -> None:
        self.sock.sendto(pack_message(message(arbitration_id, is_remote, dlc, data)), self.destination)


def port_for(bus):
    """The fast port for a udp_multicast bus that exposes its socket as expected, else the generic one."""
    mc = getattr(bus, "_multicast", None)
    if mc is not None and all(hasattr(mc, a) for a in ("_socket", "_send_destination", "max_buffer",
                                                        "received_ancillary_buffer_size", "received_timestamp_struct")):
        return UdpMulticastPort(bus)
    return BusPort(bus)
