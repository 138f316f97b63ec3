"""Reading a sharedctl MCAP recording sequentially — complete, or cut short by a crash.

The mcap library's indexed reader (``make_reader(...).iter_messages()``) needs the summary
section and footer that only a cleanly closed recording has, and its stream reader raises on
the first incomplete record. A recorder killed with SIGKILL leaves a file that ends in the
middle of (or just after) a chunk: :class:`RecordingReader` reads records in file order with
the stream reader and stops at the first incomplete one, so everything up to the last
complete chunk is returned, and says whether the file was complete.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from mcap.records import Attachment, Channel, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from .json_schemas import UNDECODED_TOPIC, VIEW_PREFIX


@dataclass(frozen=True)
class RecordedMessage:
    """One message as recorded: topic (the Zenoh key), its schema's name, times in Unix ns, JSON body."""

    topic: str
    schema: str
    log_time: int
    publish_time: int
    sequence: int
    data: bytes

    def json(self) -> dict[str, Any]:
        return json.loads(self.data)

    @property
    def undecoded(self) -> bool:
        return self.topic == UNDECODED_TOPIC

    @property
    def view(self) -> bool:
        """A derived view (foxglove.Log, foxglove.SceneUpdate), not a message that crossed Zenoh."""
        return self.topic.startswith(VIEW_PREFIX + "/")


@dataclass
class ReadStatus:
    """How far the file could be read."""

    complete: bool = False             # the footer was reached: a cleanly closed file
    stopped_by: str | None = None      # the error at the first incomplete record, if any
    messages: int = 0
    records: int = 0                   # 0 after reading: not an MCAP file at all
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: list[Attachment] = field(default_factory=list)
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)


class RecordingReader:
    """``for m in RecordingReader(path).messages(): ...``; ``status`` is filled as it reads."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        self.status = ReadStatus()

    def records(self) -> Iterator[Any]:
        """Every record in file order (chunks opened), up to the first incomplete one."""
        self.status = status = ReadStatus()
        with open(self.path, "rb") as stream:
            reader = StreamReader(stream, skip_magic=False, validate_crcs=True)
            try:
                for record in reader.records:
                    status.records += 1
                    if isinstance(record, Schema):
                        status.schemas[record.id] = record
                    elif isinstance(record, Channel):
                        status.channels[record.id] = record
                    elif isinstance(record, Metadata):
                        status.metadata[record.name] = dict(record.metadata)
                    elif isinstance(record, Attachment):
                        status.attachments.append(record)
                    elif isinstance(record, Message):
                        status.messages += 1
                    elif isinstance(record, (Footer, DataEnd)):
                        status.complete = status.complete or isinstance(record, Footer)
                    yield record
            except Exception as exc:  # noqa: BLE001 — any parse error ends the readable part
                # the tail a crash left behind: report it, keep what was complete
                status.stopped_by = f"{type(exc).__name__}: {exc}".strip(": ")
        if status.complete:
            status.stopped_by = None

    def messages(self) -> Iterator[RecordedMessage]:
        """Every complete message, in file order (which is log-time order for a sharedctl recording)."""
        for record in self.records():
            if isinstance(record, Message):
                channel = self.status.channels.get(record.channel_id)
                if channel is None:
                    continue
                schema = self.status.schemas.get(channel.schema_id)
                yield RecordedMessage(channel.topic, schema.name if schema else "", record.log_time,
                                      record.publish_time, record.sequence, bytes(record.data))

    def metadata(self) -> dict[str, dict[str, str]]:
        """The metadata records (written at the start of the file, so read without the messages)."""
        for record in self.records():
            if isinstance(record, (Message, Schema, Channel)):
                break
        return dict(self.status.metadata)


class NotARecording(ValueError):
    """The file does not even start like an MCAP file."""


def check_readable(status: ReadStatus, path) -> None:
    """Raise :class:`NotARecording` if nothing could be read from ``path``."""
    if status.records == 0:
        raise NotARecording(f"{path}: not an MCAP file ({status.stopped_by})")


def read_all(path: Path | str) -> tuple[list[RecordedMessage], ReadStatus]:
    """All readable messages and the read status."""
    reader = RecordingReader(path)
    messages = list(reader.messages())
    return messages, reader.status
