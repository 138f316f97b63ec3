"""The processes' Prometheus exporter: `--metrics HOST:PORT` on `sharedctl robot` and `sharedctl controller`.

Each process registers its collector (services/controller/metrics.py, services/robot/metrics.py) and
prometheus_client's process collector (CPU, memory, file descriptors) in a registry of its own — not the
library's global one, no platform or GC collectors — and serves it over HTTP on a daemon thread
(`serve`). A collector reads the counters the process already keeps, at scrape time, on the server's
thread: nothing is added to the loops, and a process started without `--metrics` runs no server and
does not import prometheus_client.

A scrape is Python work on that thread, about a millisecond and a half of it, and while it holds the
interpreter lock a loop thread that wakes for its tick waits. So the server keeps it short and rare:
it sleeps briefly after each metric family (`GilPausing`: the lock is free between families, so the
loop waits at most for one family's rendering, about 0.1 ms, not for the scrape), it serves one request
at a time and at most one per `MIN_INTERVAL` (a local client hammering the port is slowed down, not
the loop), and a client gets `REQUEST_TIMEOUT` to send its request and read the answer. The controller
runs this thread at a real-time priority below its loop's (controller/priority.py), so that no other
process preempts it while it holds the lock.

The address (`parse_address`): `PORT` (on 127.0.0.1), `HOST:PORT` or `[V6]:PORT`; HOST an IP address
or `localhost`. A host that is not a loopback address is refused unless `--metrics-allow-remote` is
given too (the endpoint has no authentication: put it behind a proxy that has). Port 0 takes a free
port; the process prints the address it bound.
"""
from __future__ import annotations

import ipaddress
import math
import socket
import threading
import time
from dataclasses import dataclass
from wsgiref.simple_server import WSGIRequestHandler, WSGIServer, make_server

DEFAULT_HOST = "127.0.0.1"
UNITS = ("seconds", "hertz", "ratio", "bytes")   # the base units the metric names end in
ALLOW_REMOTE_OPTION = "--metrics-allow-remote"
POLL_INTERVAL = 0.05    # s: how long `close` waits, at most, for an idle server's loop to notice
MIN_INTERVAL = 0.2      # s between the starts of two requests served (more wait in the listen backlog)
REQUEST_TIMEOUT = 1.0   # s a client may take to send its request or read the answer
GIL_PAUSE = 5e-5        # s slept after each metric family is collected (`GilPausing`)


class MetricsAddressError(ValueError):
    """A `--metrics` value that cannot be used (not HOST:PORT, a bad port, a refused host)."""


@dataclass(frozen=True)
class MetricsAddress:
    host: str     # an IP address literal
    port: int     # 0: a free port, chosen when the server binds


def parse_address(text: str, allow_remote: bool = False) -> MetricsAddress:
    """`PORT`, `HOST:PORT` or `[V6]:PORT` → a `MetricsAddress`; a non-loopback HOST only with `allow_remote`."""
    text = text.strip()
    host, sep, port_text = text.rpartition(":")
    if not sep:
        host, port_text = DEFAULT_HOST, text
    elif host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    elif ":" in host:
        raise MetricsAddressError(f"--metrics {text!r}: write an IPv6 address in brackets, [::1]:PORT")
    if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise MetricsAddressError(f"--metrics {text!r}: the port must be a number from 0 to 65535")
    if host == "localhost":
        host = DEFAULT_HOST
    try:
        ip = ipaddress.ip_address(host)
    except ValueError:
        raise MetricsAddressError(f"--metrics {text!r}: the host must be an IP address or localhost") from None
    if not ip.is_loopback and not allow_remote:
        raise MetricsAddressError(f"--metrics {text!r}: {host} is not a loopback address; the endpoint has no "
                                  f"authentication: give {ALLOW_REMOTE_OPTION} too to serve it there")
    return MetricsAddress(str(ip), int(port_text))


def unit_of(name: str) -> str:
    """The base unit a metric's name ends in (before `_total`), "" for a count or a state: OpenMetrics' UNIT."""
    base = name.removesuffix("_total")
    return next((unit for unit in UNITS if base.endswith("_" + unit)), "")


def add_arguments(parser) -> None:
    parser.add_argument("--metrics", metavar="HOST:PORT",
                        help="serve Prometheus metrics at http://HOST:PORT/metrics (a bare PORT: on 127.0.0.1; "
                             "0: a free port, printed; docs/metrics.md). Default: none")
    parser.add_argument(ALLOW_REMOTE_OPTION, action="store_true",
                        help="let --metrics bind a host that is not a loopback address (the endpoint has no "
                             "authentication)")


def address_from_args(args) -> MetricsAddress | None:
    """The parsed `--metrics` option, None without it (raises `MetricsAddressError`)."""
    if args.metrics is None:
        return None
    return parse_address(args.metrics, args.metrics_allow_remote)


class _QuietHandler(WSGIRequestHandler):
    timeout = REQUEST_TIMEOUT

    def log_message(self, format, *args) -> None:
        """No access log on stderr."""


class _Server(WSGIServer):
    """One request at a time (`MetricsServer` paces them); a failed request (a client that stalled or went
    away) is dropped quietly."""

    timeout = POLL_INTERVAL            # `handle_request` waits this long for a connection
    last_request = -math.inf           # s, monotonic: when the last request began

    def process_request(self, request, client_address) -> None:
        self.last_request = time.monotonic()
        super().process_request(request, client_address)

    def handle_error(self, request, client_address) -> None:
        pass


class GilPausing:
    """`collector`'s families, with a short sleep after each (the interpreter lock is released: a loop
    thread that woke meanwhile takes it instead of waiting for the whole scrape)."""

    def __init__(self, collector) -> None:
        self.collector = collector

    def collect(self):
        for family in self.collector.collect():
            yield family
            time.sleep(GIL_PAUSE)


class MetricsServer:
    """`registry` served at `/metrics` (any path, as prometheus_client does) on `address` by one daemon thread,
    one request at a time and at most one per `min_interval` s (the others wait in the listen backlog).
    `host`, `port`: where it is bound; `close()` stops it and frees the port."""

    def __init__(self, address: MetricsAddress, registry, min_interval: float = MIN_INTERVAL,
                 thread_setup=None) -> None:
        from prometheus_client import make_wsgi_app

        family = socket.AF_INET6 if ipaddress.ip_address(address.host).version == 6 else socket.AF_INET
        server_class = type("MetricsWSGIServer", (_Server,), {"address_family": family})
        self.server = make_server(address.host, address.port, make_wsgi_app(registry), server_class,
                                  handler_class=_QuietHandler)
        self.host, self.port = address.host, self.server.server_address[1]
        self.min_interval = min_interval
        self._closing = threading.Event()
        self._setup, self.set_up = thread_setup, threading.Event()
        self.setup_result = None           # what `thread_setup` returned, in the server's thread
        self.thread = threading.Thread(target=self._serve, name="metrics", daemon=True)
        self.thread.start()
        self.set_up.wait()

    def _serve(self) -> None:
        try:
            self.setup_result = self._setup() if self._setup is not None else None
        finally:
            self.set_up.set()
        while not self._closing.is_set():
            self.server.handle_request()
            wait = self.server.last_request + self.min_interval - time.monotonic()
            if wait > 0.0:
                self._closing.wait(wait)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/metrics"

    def close(self) -> None:
        """Stop serving (a request under way may finish, within REQUEST_TIMEOUT) and close the port."""
        self._closing.set()
        self.thread.join(timeout=REQUEST_TIMEOUT)
        self.server.server_close()


def serve(address: MetricsAddress, *collectors, min_interval: float = MIN_INTERVAL,
          thread_setup=None) -> MetricsServer:
    """A registry of its own holding `collectors` (objects with `collect()`) and prometheus_client's process
    collector (`process_cpu_seconds_total`, `process_resident_memory_bytes`, open files, …, from /proc),
    each behind `GilPausing`, served on `address`; `thread_setup()` runs first in the server's thread (the
    controller's raises its priority: controller/priority.py), its result kept as `setup_result`."""
    from prometheus_client import CollectorRegistry, ProcessCollector

    registry = CollectorRegistry(auto_describe=False)
    for collector in (*collectors, ProcessCollector(registry=None)):
        registry.register(GilPausing(collector))
    return MetricsServer(address, registry, min_interval, thread_setup)
