"""The live view's WebSocket address: ``HOST:PORT``, loopback unless the user allows another host."""
from __future__ import annotations

import ipaddress


class AddressError(ValueError):
    """A --listen address that is malformed, or not loopback without --allow-remote."""


def listen_address(text: str, allow_remote: bool = False, option: str = "--listen") -> tuple[str, int]:
    """``HOST:PORT`` (``[::1]:PORT`` for IPv6) as (host, port); a non-loopback host only with ``allow_remote``
    (``option`` names the command-line option in the error)."""
    host, sep, port = text.rpartition(":")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not sep or not host or not port.isdigit() or not 0 <= int(port) < 65536:
        raise AddressError(f"{option} {text!r}: expected HOST:PORT")
    if host != "localhost":
        try:
            loopback = ipaddress.ip_address(host).is_loopback
        except ValueError:
            raise AddressError(f"{option} {text!r}: the host must be an IP address or localhost") from None
        if not loopback and not allow_remote:
            raise AddressError(f"{option} {text!r}: not a loopback address; the WebSocket server has no "
                               "authentication: other hosts only with `sharedctl foxglove --allow-remote`")
    return host, int(port)
