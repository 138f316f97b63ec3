"""MCAP recorder of Zenoh messages: one channel per key and kind, JSON with a JSON Schema, crash-tolerant.

Each received payload is queued by the Zenoh callback (nothing but a clock read and a queue
put happens there) and written by one writer thread:

* decoded with the wire codec (``decode_message``, any array lengths) and written as the JSON
  of its MessagePack map on the channel ``<key>`` with the schema of its kind
  (:mod:`.json_schemas`) — Foxglove reads these channels as they are;
* a payload the codec refuses is kept byte for byte on ``sharedctl/undecoded`` with the key
  and the error, and counted.

Times: ``log_time`` is this host's clock (Unix ns) when the sample arrived; ``publish_time`` is
the Zenoh timestamp when the sender attached one, else the message's own time field
(``send_time`` of an operator command, ``time`` of the others: the sender's own clock, Unix time
for most, the simulator's clock for GroundTruth and the robot's heartbeat), in ns.

Crash tolerance: the file is chunked (zstd) and the chunk in progress is closed and handed to
the operating system every :data:`FLUSH_PERIOD` seconds, so a process killed with SIGKILL
loses at most that much (plus what was still queued). Such a file has no summary section; it
reads sequentially up to the last complete chunk (:mod:`.mcap_reading`), and ``sharedctl
record-recover`` rewrites it as a complete, indexed file (docs/recording.md).
"""
from __future__ import annotations

import base64
import json
import queue
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from mcap.writer import CompressionType, Writer

from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.msgpack_codec import decode_message, to_map

from .background import lower_this_thread
from .json_schemas import (
    MESSAGE_ENCODING,
    MESSAGE_SCHEMAS,
    SCHEMA_ENCODING,
    UNDECODED_SCHEMA,
    UNDECODED_SCHEMA_NAME,
    UNDECODED_TOPIC,
    schema_bytes,
)

FLUSH_PERIOD = 0.25          # s between chunk flushes: the most a SIGKILL can lose from the file
MAX_QUEUED = 200_000         # samples waiting for the writer; beyond this they are counted as dropped
CHUNK_SIZE = 1 << 20         # bytes; chunks are closed by time long before they reach this
_STOP = object()
_FLUSH = object()
_U64 = 1 << 64


@dataclass
class RecorderCounts:
    """What the recorder did, for the run's summary."""

    messages: int = 0
    undecoded: int = 0
    dropped: int = 0            # queue full or writer failed
    flushes: int = 0
    write_error: str | None = None
    per_topic: dict[str, int] = field(default_factory=dict)


def zenoh_time_ns(timestamp) -> int | None:
    """A Zenoh ``Timestamp`` as Unix ns, or None when the sample carries none."""
    if timestamp is None:
        return None
    try:
        return int(timestamp.get_time().timestamp() * 1e9)
    except (AttributeError, ValueError, OverflowError, OSError):
        return None


def _message_time_ns(message, fallback: int) -> int:
    seconds = getattr(message, "send_time", None)
    if seconds is None:
        seconds = getattr(message, "time", None)
    if seconds is None:
        return fallback
    ns = int(seconds * 1e9)
    return ns if 0 <= ns < _U64 else fallback


class McapRecorder:
    """Records (key, payload) samples to an MCAP file from any thread; ``close()`` finishes the file."""

    def __init__(self, path: Path, metadata: dict[str, dict[str, str]], library: str = "sharedctl",
                 flush_period: float = FLUSH_PERIOD) -> None:
        self.path = Path(path)
        self.counts = RecorderCounts()
        self.flush_period = flush_period
        self._file = open(self.path, "wb")
        self._writer = Writer(self._file, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library=library)
        for name, data in metadata.items():
            self._writer.add_metadata(name, {k: str(v) for k, v in data.items()})
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._writer.flush()
        self._queue: queue.Queue = queue.Queue(MAX_QUEUED)
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="mcap-recorder", daemon=True)
        self._thread.start()

    # ----- producers (any thread) -------------------------------------------------------
    def put(self, key: str, payload: bytes, log_time_ns: int | None = None, publish_time_ns: int | None = None) -> None:
        """Queue one sample; never blocks, never raises (a full queue is counted as a drop)."""
        if self._closed:
            return
        try:
            self._queue.put_nowait((key, bytes(payload), log_time_ns or time.time_ns(), publish_time_ns))
        except queue.Full:
            self.counts.dropped += 1

    def flush(self) -> None:
        """Close the chunk in progress after what is queued now (the writer also does so every flush period)."""
        if not self._closed:
            self._queue.put(_FLUSH)

    def on_sample(self, sample) -> None:
        """Zenoh subscriber callback."""
        self.put(str(sample.key_expr), sample.payload.to_bytes(), time.time_ns(), zenoh_time_ns(sample.timestamp))

    def close(self, timeout: float = 5.0) -> RecorderCounts:
        """Write what is queued, the summary section and the footer; close the file."""
        if not self._closed:
            self._closed = True
            self._queue.put(_STOP)
            self._thread.join(timeout)
        return self.counts

    # ----- the writer thread -----------------------------------------------------------
    def _run(self) -> None:
        lower_this_thread()
        next_flush = time.monotonic() + self.flush_period
        dirty = False
        while True:
            try:
                item = self._queue.get(timeout=max(0.0, next_flush - time.monotonic()))
            except queue.Empty:
                item = None
            if item is _STOP:
                break
            if item is _FLUSH:
                next_flush = 0.0
            elif item is not None:
                self._write(*item)
                dirty = True
            if time.monotonic() >= next_flush:
                if dirty:
                    self._flush()
                    dirty = False
                next_flush = time.monotonic() + self.flush_period
        while True:      # what arrived before close()
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                break
            if item is not _STOP and item is not _FLUSH:
                self._write(*item)
        self._finish()

    def _flush(self) -> None:
        if self.counts.write_error:
            return
        try:
            self._writer.flush()
            self.counts.flushes += 1
        except OSError as exc:
            self._fail(exc)

    def _finish(self) -> None:
        try:
            if not self.counts.write_error:
                self._writer.finish()
        except OSError as exc:
            self._fail(exc)
        finally:
            self._file.close()

    def _fail(self, exc: OSError) -> None:
        self.counts.write_error = f"{type(exc).__name__}: {exc}"

    def _write(self, key: str, payload: bytes, log_ns: int, publish_ns: int | None) -> None:
        if self.counts.write_error:
            self.counts.dropped += 1
            return
        try:
            message = decode_message(payload, None)
        except ProtocolError as exc:
            self._write_undecoded(key, payload, log_ns, f"{type(exc).__name__}: {exc}")
            return
        except Exception as exc:  # noqa: BLE001 — a codec bug must not lose the payload
            self._write_undecoded(key, payload, log_ns, f"{type(exc).__name__}: {exc}")
            return
        channel = self._channel(key, message.KIND)
        data = json.dumps(to_map(message), separators=(",", ":")).encode()
        publish = publish_ns if publish_ns is not None else _message_time_ns(message, log_ns)
        sequence = getattr(message, "seq", 0) & 0xFFFFFFFF
        self._add(channel, key, log_ns, data, publish, sequence)

    def _write_undecoded(self, key: str, payload: bytes, log_ns: int, error: str) -> None:
        self.counts.undecoded += 1
        channel = self._channel(UNDECODED_TOPIC, UNDECODED_SCHEMA_NAME)
        data = json.dumps({"key": key, "error": error[:512], "size": len(payload),
                           "payload_base64": base64.b64encode(payload).decode()}).encode()
        self._add(channel, UNDECODED_TOPIC, log_ns, data, log_ns, 0)

    def _add(self, channel: int, topic: str, log_ns: int, data: bytes, publish_ns: int, sequence: int) -> None:
        try:
            self._writer.add_message(channel, log_time=log_ns, data=data, publish_time=publish_ns, sequence=sequence)
        except OSError as exc:
            self._fail(exc)
            self.counts.dropped += 1
            return
        self.counts.messages += 1
        self.counts.per_topic[topic] = self.counts.per_topic.get(topic, 0) + 1

    def _channel(self, topic: str, kind: str) -> int:
        channel = self._channels.get((topic, kind))
        if channel is None:
            schema = self._schemas.get(kind)
            if schema is None:
                body = UNDECODED_SCHEMA if kind == UNDECODED_SCHEMA_NAME else MESSAGE_SCHEMAS[kind]
                schema = self._writer.register_schema(body["title"], SCHEMA_ENCODING, schema_bytes(body))
                self._schemas[kind] = schema
            channel = self._writer.register_channel(topic, MESSAGE_ENCODING, schema, {"kind": kind})
            self._channels[(topic, kind)] = channel
        return channel
