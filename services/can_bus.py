"""Opening the CAN bus: SocketCAN where the kernel has it, host-local UDP multicast otherwise.

`--can-interface NAME --can-channel CH [--can-option key=value …]` are passed to
`can.Bus(interface=NAME, channel=CH, **options)`. With no interface given, the default is
SocketCAN on `vcan0` when that interface exists (Linux with the vcan module; see
deploy/vcan-setup.sh), and otherwise python-can's `udp_multicast` on the IPv4 group
239.74.163.2 with `hop_limit=0`, so frames never leave this host. udp_multicast always gets
hop_limit=0 here, whatever the options say.

Note: on udp_multicast a bus also receives the frames it sends itself (multicast loopback);
every receiver in this project ignores frames of the direction it sends.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import can

UDP_GROUP = "239.74.163.2"
DEFAULT_UDP_PORT = 43113


@dataclass(frozen=True)
class BusSpec:
    interface: str
    channel: str
    options: dict = field(default_factory=dict)

    def describe(self) -> str:
        opts = " ".join(f"{k}={v}" for k, v in sorted(self.options.items()))
        return f"{self.interface}:{self.channel}" + (f" ({opts})" if opts else "")


def vcan_available(name: str = "vcan0") -> bool:
    return os.path.exists(f"/sys/class/net/{name}")


def parse_options(pairs: list[str] | None) -> dict:
    """`key=value` strings → dict, with ints, floats and booleans recognised."""
    options: dict = {}
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise ValueError(f"--can-option expects key=value, got {pair!r}")
        low = value.lower()
        if low in ("true", "false"):
            options[key] = low == "true"
        else:
            try:
                options[key] = int(value)
            except ValueError:
                try:
                    options[key] = float(value)
                except ValueError:
                    options[key] = value
    return options


def resolve(interface: str | None, channel: str | None, options: dict | None = None, udp_port: int | None = None) -> BusSpec:
    """Choose the bus: explicit arguments, else vcan0, else host-local udp_multicast."""
    options = dict(options or {})
    if interface is None:
        if vcan_available():
            interface, channel = "socketcan", channel or "vcan0"
        else:
            interface, channel = "udp_multicast", channel or UDP_GROUP
    if interface == "udp_multicast":
        channel = channel or UDP_GROUP
        options.setdefault("port", udp_port or DEFAULT_UDP_PORT)
        options["hop_limit"] = 0          # host-local, always
        options.setdefault("fd", False)   # classic CAN frames, as an ODrive speaks
    elif channel is None:
        raise ValueError(f"--can-channel is required with --can-interface {interface}")
    return BusSpec(interface, channel, options)


#: receive buffer asked for on udp_multicast sockets: the default (~208 KiB) overflows when a
#: reader stalls for a few tens of milliseconds behind 3,000 frames/s
UDP_RECEIVE_BUFFER = 4 * 1024 * 1024


def open_bus(spec: BusSpec) -> can.BusABC:
    """Open the bus; the caller must `shutdown()` it."""
    bus = can.Bus(interface=spec.interface, channel=spec.channel, **spec.options)
    if spec.interface == "udp_multicast":
        _enlarge_receive_buffer(bus)
    return bus


def _enlarge_receive_buffer(bus) -> None:
    """Best effort: SO_RCVBUFFORCE (needs CAP_NET_ADMIN), else SO_RCVBUF (capped by rmem_max)."""
    import socket

    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None:
        return
    for option in (getattr(socket, "SO_RCVBUFFORCE", None), socket.SO_RCVBUF):
        if option is None:
            continue
        try:
            sock.setsockopt(socket.SOL_SOCKET, option, UDP_RECEIVE_BUFFER)
            return
        except OSError:
            continue


def add_arguments(parser) -> None:
    """The CAN options every CAN-speaking command takes."""
    parser.add_argument("--can-interface", help="python-can interface (default: socketcan if vcan0 exists, else udp_multicast)")
    parser.add_argument("--can-channel", help="channel (default: vcan0, or the multicast group for udp_multicast)")
    parser.add_argument("--can-option", action="append", metavar="KEY=VALUE", help="extra can.Bus option (repeatable)")


def spec_from_args(args) -> BusSpec:
    return resolve(args.can_interface, args.can_channel, parse_options(args.can_option))
