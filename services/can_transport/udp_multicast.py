"""CAN over host-local UDP multicast, python-can's `udp_multicast` format, on a socket of its own.

:class:`UdpMulticastTransport` opens its socket as python-can's `UdpMulticastBus` does
(can/interfaces/udp_multicast/bus.py): the group's address family from `getaddrinfo` (IPv4 or
IPv6), the multicast TTL / hop limit, SO_REUSEADDR and SO_REUSEPORT, kernel receive timestamps
(SO_TIMESTAMPNS), bound to the port on every interface, the group joined — with the hop limit
always 0, so no frame leaves this host, multicast loopback on, so every transport and python-can
bus of the group on this host hears every frame (its own included), and a receive buffer large
enough for a reader that stalls behind 3,000 frames/s. A frame is the datagram python-can writes:
the MessagePack map of every `can.Message` field (`datagram`, byte for byte python-can's
`pack_message`, checked by tests/services/test_can_transport.py), so this transport and
python-can buses (the recorder, the bench's listener, the tests' listeners) share a group.

Reading takes only the fields a CAN node needs, with the kernel's receive time; forwarding a frame
unchanged resends its datagram as it came. Neither builds a `can.Message`.
"""
from __future__ import annotations

import errno
import select
import socket
import struct
import time

import msgpack

from .base import Frame, Transport, UnreadableFrame

DEFAULT_GROUP = "239.74.163.2"       # python-can's DEFAULT_GROUP_IPv4
DEFAULT_PORT = 43113                 # python-can's default port
#: receive buffer asked for: the default (~208 KiB) overflows when a reader stalls for a few tens
#: of milliseconds behind 3,000 frames/s
RECEIVE_BUFFER = 4 * 1024 * 1024
MAX_DATAGRAM = 4096                  # python-can's max_buffer
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)    # python-can's constant (Linux)
_TIMESPEC = struct.Struct("@ll")     # struct timespec, as python-can reads it
_ANCILLARY = socket.CMSG_SPACE(_TIMESPEC.size)


class UnreadableDatagram(UnreadableFrame):
    """A udp_multicast datagram that is not a classic CAN frame in python-can's format."""


# --- the datagram, python-can's `pack_message(can.Message(...))`, from pieces msgpack packs once ----
def _packed(*values) -> bytes:
    return b"".join(msgpack.packb(v, use_bin_type=True) for v in values)


_HEAD = bytes([0x80 | 11]) + _packed("timestamp", 0.0, "arbitration_id")    # a map of 11 fields
_IDS = tuple(_packed(n) for n in range(0x800))                                # 11-bit standard ids
_FLAGS = {remote: _packed("is_extended_id", False, "is_remote_frame", remote, "is_error_frame", False,
                          "channel", None, "dlc") for remote in (False, True)}
_DLCS = tuple(_packed(n) for n in range(9))
_DATA_KEY = _packed("data")
_BIN_HEADS = tuple(_packed(bytes(n))[:-n or None] for n in range(9))
_TAIL = _packed("is_fd", False, "bitrate_switch", False, "error_state_indicator", False)


def datagram(arbitration_id: int, is_remote: bool, dlc: int, data: bytes) -> bytes:
    """The udp_multicast datagram of a classic standard-id frame: python-can's `pack_message` of the
    `can.Message` with these fields (timestamp 0, channel None), without the Message."""
    if is_remote:
        data = b""
    if (type(arbitration_id) is int and 0 <= arbitration_id < 0x800 and type(is_remote) is bool
            and type(dlc) is int and 0 <= dlc <= 8 and len(data) <= 8):
        return b"".join((_HEAD, _IDS[arbitration_id], _FLAGS[is_remote], _DLCS[dlc], _DATA_KEY,
                         _BIN_HEADS[len(data)], data, _TAIL))
    return msgpack.packb({     # not a classic standard-id frame: msgpack writes the same map itself
        "timestamp": 0.0, "arbitration_id": arbitration_id, "is_extended_id": False, "is_remote_frame": is_remote,
        "is_error_frame": False, "channel": None, "dlc": dlc, "data": bytes(data),
        "is_fd": False, "bitrate_switch": False, "error_state_indicator": False,
    }, use_bin_type=True)


# --- the socket ------------------------------------------------------------------------------------
def enlarge_receive_buffer(sock: socket.socket, size: int = RECEIVE_BUFFER) -> None:
    """Best effort: SO_RCVBUFFORCE (needs CAP_NET_ADMIN), else SO_RCVBUF (capped by rmem_max)."""
    for option in (getattr(socket, "SO_RCVBUFFORCE", None), socket.SO_RCVBUF):
        if option is None:
            continue
        try:
            sock.setsockopt(socket.SOL_SOCKET, option, size)
            return
        except OSError:
            continue


def _open_socket(family: socket.AddressFamily, group: str, port: int) -> tuple[socket.socket, bool]:
    """python-can's `_create_socket` with hop limit 0 and loopback on; (socket, kernel timestamps on)."""
    sock = socket.socket(family, socket.SOCK_DGRAM)
    try:
        hops = struct.pack("@I", 0)
        if family == socket.AF_INET:
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, hops)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
        else:
            sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS, hops)
            sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_LOOP, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if hasattr(socket, "SO_REUSEPORT"):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        try:
            sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            stamped = True
        except OSError as exc:
            if exc.errno not in (errno.ENOPROTOOPT, errno.EINVAL):
                raise
            stamped = False
        sock.bind(("", port))
        group_bytes = socket.inet_pton(family, group)
        if family == socket.AF_INET:
            request = group_bytes + struct.pack("@I", socket.INADDR_ANY)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, request)
        else:
            sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_JOIN_GROUP, group_bytes + struct.pack("@I", 0))
        enlarge_receive_buffer(sock)
        return sock, stamped
    except OSError:
        sock.close()
        raise


class UdpMulticastTransport(Transport):
    """A python-can udp_multicast bus (group `channel`, `port`), read and written on a socket of its own.

    `hop_limit` must be 0 (nothing leaves this host) and `fd` False (classic CAN, as an ODrive
    speaks); they are accepted so that python-can's options can be passed as they are. `send` is a
    `sendto` (blocking: a UDP send waits only while the socket's send buffer is full); `timeout`
    is accepted for the signature of :class:`Transport`."""

    UNREADABLE = (UnreadableDatagram,)

    def __init__(self, channel: str = DEFAULT_GROUP, port: int = DEFAULT_PORT, hop_limit: int = 0,
                 fd: bool = False) -> None:
        if hop_limit != 0:
            raise ValueError(f"udp_multicast hop_limit must be 0 (host-local), got {hop_limit!r}")
        if fd:
            raise ValueError("udp_multicast carries classic CAN frames here: fd must be False")
        errors = []
        for family, *_ in socket.getaddrinfo(channel, port, type=socket.SOCK_DGRAM):
            try:
                self.sock, stamped = _open_socket(family, channel, port)
                break
            except OSError as exc:
                errors.append(exc)
        else:
            raise OSError(f"cannot join the multicast group {channel} port {port}: {errors}")
        self.channel, self.port = channel, port
        self.destination = (channel, port)
        self.ancillary = _ANCILLARY if stamped else 0
        self.bad = 0

    def fileno(self) -> int:
        return self.sock.fileno()

    def shutdown(self) -> None:
        self.sock.close()

    def recv(self, timeout: float | None) -> Frame | None:
        """One frame, waiting up to `timeout` s; None if none came. A datagram that is not a frame
        raises UnreadableDatagram (after it has been consumed: the next call reads on)."""
        try:
            raw, ancillary, _, _ = self.sock.recvmsg(MAX_DATAGRAM, self.ancillary, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            if (timeout is not None and timeout <= 0.0) or not select.select([self.sock], [], [], timeout)[0]:
                return None
            try:
                raw, ancillary, _, _ = self.sock.recvmsg(MAX_DATAGRAM, self.ancillary, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                return None
        return self._frame(raw, ancillary)

    def _frame(self, raw: bytes, ancillary) -> Frame:
        try:
            d = msgpack.unpackb(raw, raw=False)
            if d.get("is_fd"):
                raise ValueError("CAN FD frame on a classic CAN bus")
            arbitration_id, is_remote, dlc, data = d["arbitration_id"], d["is_remote_frame"], d["dlc"], d["data"]
            is_extended, is_error = d["is_extended_id"], d["is_error_frame"]
        except (ValueError, KeyError, TypeError, AttributeError, msgpack.UnpackException) as exc:
            raise UnreadableDatagram(f"not a classic CAN frame: {type(exc).__name__}") from None
        if not (type(arbitration_id) is int and type(dlc) is int and type(data) is bytes and type(is_remote) is bool
                and type(is_extended) is bool and type(is_error) is bool):
            raise UnreadableDatagram("not a classic CAN frame: a field of the wrong type")
        if ancillary and len(ancillary[0][2]) == _TIMESPEC.size:
            seconds, nanoseconds = _TIMESPEC.unpack(ancillary[0][2])
            arrival = seconds + nanoseconds * 1e-9
        else:
            arrival = time.time()       # no kernel timestamp: now, when it is read
        return Frame(arbitration_id, is_remote, is_extended, is_error, dlc, data, arrival, raw)

    def forward(self, frame: Frame) -> None:
        self.sock.sendto(frame.raw, self.destination)

    def send(self, arbitration_id: int, is_remote: bool, dlc: int, data: bytes, timeout: float | None = None) -> None:
        self.sock.sendto(datagram(arbitration_id, is_remote, dlc, data), self.destination)


def open_transport(channel: str, options: dict) -> UdpMulticastTransport:
    """The transport of a resolved bus (services/can_bus.py): python-can's udp_multicast options
    `port`, `hop_limit` (0) and `fd` (False); any other option is refused by name."""
    unknown = sorted(set(options) - {"port", "hop_limit", "fd"})
    if unknown:
        raise ValueError(f"udp_multicast transport: unsupported option(s) {', '.join(unknown)}")
    return UdpMulticastTransport(channel, **options)
