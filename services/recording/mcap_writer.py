"""MCAP recorder of Zenoh messages: one channel per key and kind, JSON with a JSON Schema, crash-tolerant.

Each received payload is queued by the Zenoh callback (nothing but a clock read and a queue
put happens there) and written by one writer thread:

* decoded with the wire codec and written as the JSON of its MessagePack map on the channel
  ``<key>`` with the schema of its kind (:mod:`.json_form`, the codec the live view shares) —
  Foxglove reads these channels as they are;
* a payload the codec refuses is kept byte for byte on ``sharedctl/undecoded`` with the key
  and the error, and counted;
* with ``derive``, the records it makes of each decoded message are written too (the live
  view's ``foxglove.Log`` and ``foxglove.SceneUpdate`` channels, docs/foxglove.md).

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

import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from mcap.writer import CompressionType, Writer

from .background import lower_this_thread
from .json_form import JsonRecord, wire_record, zenoh_time_ns
from .json_schemas import MESSAGE_ENCODING, SCHEMA_ENCODING, schema_bytes

FLUSH_PERIOD = 0.25          # s between chunk flushes: the most a SIGKILL can lose from the file
MAX_QUEUED = 200_000         # samples waiting for the writer; beyond this they are counted as dropped
CHUNK_SIZE = 1 << 20         # bytes; chunks are closed by time long before they reach this
_STOP = object()
_FLUSH = object()


@dataclass
class RecorderCounts:
    """What the recorder did, for the run's summary."""

    messages: int = 0
    undecoded: int = 0
    dropped: int = 0            # queue full or writer failed
    flushes: int = 0
    write_error: str | None = None
    derive_errors: int = 0      # decoded messages whose derived records could not be made
    derive_error: str | None = None   # the first such error
    per_topic: dict[str, int] = field(default_factory=dict)


class McapRecorder:
    """Records (key, payload) samples to an MCAP file from any thread; ``close()`` finishes the file."""

    def __init__(self, path: Path, metadata: dict[str, dict[str, str]], library: str = "sharedctl",
                 flush_period: float = FLUSH_PERIOD,
                 derive: Callable[[JsonRecord], list[JsonRecord]] | None = None) -> None:
        self.path = Path(path)
        self.derive = derive
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
        record = wire_record(key, payload, log_ns, publish_ns)
        if record.message is None:
            self.counts.undecoded += 1
        self._add(record)
        if self.derive is not None and record.message is not None:
            try:
                derived = self.derive(record)
            except Exception as exc:  # noqa: BLE001 — a view that cannot be drawn must not stop the recording
                self.counts.derive_errors += 1
                self.counts.derive_error = self.counts.derive_error or f"{type(exc).__name__}: {exc}"
                return
            for extra in derived:
                self._add(extra)

    def _add(self, record: JsonRecord) -> None:
        try:
            channel = self._channel(record)
            self._writer.add_message(channel, log_time=record.log_time, data=record.data,
                                     publish_time=record.publish_time, sequence=record.sequence)
        except OSError as exc:
            self._fail(exc)
            self.counts.dropped += 1
            return
        self.counts.messages += 1
        self.counts.per_topic[record.topic] = self.counts.per_topic.get(record.topic, 0) + 1

    def _channel(self, record: JsonRecord) -> int:
        channel = self._channels.get((record.topic, record.kind))
        if channel is None:
            schema = self._schemas.get(record.schema_name)
            if schema is None:
                schema = self._writer.register_schema(record.schema_name, SCHEMA_ENCODING, schema_bytes(record.schema))
                self._schemas[record.schema_name] = schema
            channel = self._writer.register_channel(record.topic, MESSAGE_ENCODING, schema, {"kind": record.kind})
            self._channels[(record.topic, record.kind)] = channel
        return channel
