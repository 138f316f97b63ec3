"""Opening Zenoh sessions the way this project allows: loopback endpoints, no scouting.

Every process runs an embedded peer (no router): one listens on an explicit
`tcp/127.0.0.1:PORT` endpoint, the others connect to it. Multicast and gossip scouting are
off, so nothing is announced on the network, and a peer never listens on all interfaces.
"""
from __future__ import annotations

import json
import socket

import zenoh

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
# a peer that is not listening yet, or is gone, is tried again 100 ms, then every 150 to 250 ms later;
# Zenoh's default (1 s, doubling up to 4 s) made a console started before its controller wait up to a
# second for it, and a console whose controller restarted up to 4 s (the attempts are loopback connects)
CONNECT_RETRY = {"period_init_ms": 100, "period_max_ms": 250, "period_increase_factor": 1.5}


class EndpointError(ValueError):
    """An endpoint that is not an explicit loopback TCP endpoint."""


def check_loopback(endpoint: str) -> str:
    """Accept only tcp/127.x.y.z:PORT or tcp/[::1]:PORT (nothing leaves this host)."""
    if not endpoint.startswith("tcp/"):
        raise EndpointError(f"{endpoint!r}: only tcp/ endpoints are used")
    host, _, port = endpoint[4:].rpartition(":")
    if not port.isdigit() or not (0 < int(port) < 65536):
        raise EndpointError(f"{endpoint!r}: needs an explicit port")
    if not (host.startswith("127.") or host in ("[::1]", "localhost")):
        raise EndpointError(f"{endpoint!r}: not a loopback address")
    return endpoint


def config(listen: list[str] | None = None, connect: list[str] | None = None) -> zenoh.Config:
    """A peer configuration: explicit loopback listen/connect endpoints, scouting off."""
    cfg = zenoh.Config()
    cfg.insert_json5("mode", '"peer"')
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("scouting/gossip/enabled", "false")
    cfg.insert_json5("listen/endpoints", json.dumps([check_loopback(e) for e in listen or []]))
    cfg.insert_json5("connect/endpoints", json.dumps([check_loopback(e) for e in connect or []]))
    cfg.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))
    return cfg


def open_session(listen: list[str] | None = None, connect: list[str] | None = None) -> zenoh.Session:
    """Open a peer session; the caller must `close()` it (a Zenoh process that never closes can hang at exit)."""
    return zenoh.open(config(listen, connect))


def free_loopback_port() -> int:
    """A TCP port that is free on 127.0.0.1 right now (for per-run endpoints in demos and tests)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
