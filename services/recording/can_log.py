"""A candump-format log of a CAN bus: a receive-only listener and python-can's ``CanutilsLogWriter``.

The listener opens its own handle on the bus (:func:`sharedctl.services.can_bus.open_bus`, so
udp_multicast is host-local with ``hop_limit=0``) and never sends. On udp_multicast and on
SocketCAN every handle receives every frame on the bus, the controller's own commands
included, so the log holds both directions. Lines are ``candump -L`` lines::

    (1763820000.123456) vcan0 00E#0000803F T

which python-can reads back (``can.LogReader``) and cantools decodes with the DBC
(``python -m cantools decode --single-line protocol/odrive_cansimple.dbc < FILE.can.log``).
The file is flushed every :data:`FLUSH_PERIOD` seconds, so a SIGKILL loses at most that much.
"""
from __future__ import annotations

import threading
import time
from pathlib import Path

import can

from .. import can_bus
from .background import lower_this_thread

FLUSH_PERIOD = 0.25                    # s between flushes of the log file
UDP_LOG_CHANNEL = "udpmcast0"          # interface name written for frames from python-can's udp_multicast


def log_channel_name(spec: can_bus.BusSpec) -> str:
    """The interface name the log lines carry: the SocketCAN interface, or a fixed name for udp_multicast."""
    if spec.interface == "udp_multicast":
        return UDP_LOG_CHANNEL
    return str(spec.channel).replace(" ", "_") or "can0"


class CanLogger:
    """Receives every frame on the bus in a thread and appends it to a candump log."""

    def __init__(self, path: Path, spec: can_bus.BusSpec, flush_period: float = FLUSH_PERIOD) -> None:
        self.path = Path(path)
        self.spec = spec
        self.channel = log_channel_name(spec)
        self.flush_period = flush_period
        self.frames = 0
        self.errors = 0
        self.error: str | None = None
        self._stop = threading.Event()
        self._bus = can_bus.open_bus(spec)
        try:
            self._writer = can.CanutilsLogWriter(str(self.path), channel=self.channel)
        except Exception:
            self._bus.shutdown()
            raise
        self._thread = threading.Thread(target=self._run, name="can-log", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        lower_this_thread()
        next_flush = time.monotonic() + self.flush_period
        pending = False
        while not self._stop.is_set():
            try:
                message = self._bus.recv(timeout=min(0.05, self.flush_period))
            except (can.CanError, OSError, ValueError) as exc:   # a bad datagram must not end the log
                self.errors += 1
                self.error = f"{type(exc).__name__}: {exc}"
                message = None
                if isinstance(exc, OSError) and self._stop.wait(0.01):
                    break
            if message is not None:
                message.channel = self.channel
                try:
                    self._writer.on_message_received(message)
                    self.frames += 1
                    pending = True
                except (OSError, ValueError) as exc:
                    self.errors += 1
                    self.error = f"{type(exc).__name__}: {exc}"
            if pending and time.monotonic() >= next_flush:
                self._flush()
                pending = False
                next_flush = time.monotonic() + self.flush_period
            elif not pending:
                next_flush = max(next_flush, time.monotonic())

    def _flush(self) -> None:
        try:
            self._writer.file.flush()
        except (OSError, ValueError) as exc:
            self.errors += 1
            self.error = f"{type(exc).__name__}: {exc}"

    def close(self, timeout: float = 2.0) -> int:
        """Stop listening, flush and close the log; returns the number of frames written."""
        if not self._stop.is_set():
            self._stop.set()
            self._thread.join(timeout)
            try:
                self._writer.stop()
            finally:
                self._bus.shutdown()
        return self.frames
