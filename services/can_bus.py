"""Opening the CAN bus: SocketCAN where the kernel has it, host-local UDP multicast otherwise.

`--can-interface NAME --can-channel CH [--can-option key=value …]` are passed to
`can.Bus(interface=NAME, channel=CH, **options)`. With no interface given, the default is
SocketCAN on `vcan0` when that interface exists (Linux with the vcan module; see
deploy/vcan-setup.sh), and otherwise python-can's `udp_multicast` on the IPv4 group
239.74.163.2 with `hop_limit=0`, so frames never leave this host. udp_multicast always gets
hop_limit=0 here, whatever the options say.

`open_transport` gives the bus as a transport (services/can_transport/: udp_multicast on a socket
of its own, any other interface through python-can); `open_bus` gives a python-can bus, for
callers that want `can.Message`s (the recorder, the bench's listener, tests).

Note: on udp_multicast a bus also receives the frames it sends itself (multicast loopback);
every receiver in this project ignores frames of the direction it sends.
"""
from __future__ import annotations

import importlib
import os
import socket
from dataclasses import dataclass, field

import can

from . import can_transport
from .can_transport import PythonCanTransport, Transport
from .can_transport.udp_multicast import enlarge_receive_buffer

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


def resolve(interface: str | None, channel: str | None, options: dict | None = None,
            udp_port: int | None = None) -> BusSpec:
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


def open_transport(spec: BusSpec) -> Transport:
    """Open the bus as a transport (services/can_transport/); the caller must `shutdown()` it.

    The plug-in of services/can_transport/ named after the interface opens it if there is one
    (udp_multicast: a socket of its own, hop limit 0); any other interface is a python-can bus
    (`open_bus`) read and written through its public `recv`/`send`."""
    plugin, name = None, f"{can_transport.__name__}.{spec.interface}"
    if spec.interface.isidentifier():
        try:
            plugin = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
    opener = getattr(plugin, "open_transport", None)
    if opener is None:
        return PythonCanTransport(open_bus(spec))
    return opener(spec.channel, spec.options)


def open_bus(spec: BusSpec) -> can.BusABC:
    """Open the bus as a python-can bus (for callers that want `can.Message`s); the caller must `shutdown()` it."""
    bus = can.Bus(interface=spec.interface, channel=spec.channel, **spec.options)
    if spec.interface == "udp_multicast":
        _enlarge_receive_buffer(bus)
    return bus


def _enlarge_receive_buffer(bus: can.BusABC) -> None:
    """The udp_multicast transport's receive buffer (`RECEIVE_BUFFER`), best effort, on a duplicate of
    the bus's public `fileno()`."""
    with socket.socket(fileno=os.dup(bus.fileno())) as sock:
        enlarge_receive_buffer(sock)


def add_arguments(parser, default: str = "socketcan if vcan0 exists, else udp_multicast") -> None:
    """The CAN options every CAN-speaking command takes (`default`: what the command does without them)."""
    parser.add_argument("--can-interface", help=f"python-can interface (default: {default})")
    parser.add_argument("--can-channel", help="channel (default: vcan0, or the multicast group for udp_multicast)")
    parser.add_argument("--can-option", action="append", metavar="KEY=VALUE", help="extra can.Bus option (repeatable)")


def spec_from_args(args) -> BusSpec:
    return resolve(args.can_interface, args.can_channel, parse_options(args.can_option))
