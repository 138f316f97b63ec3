"""`sharedctl record-recover IN OUT` — make a recording cut short by a crash whole again.

* ``IN.mcap``: a recorder killed with SIGKILL (or a power cut) leaves a file without summary
  section and footer, possibly ending in a partial chunk. Every complete record is read in
  file order (:mod:`.mcap_reading`) and written to OUT as a complete, indexed MCAP file:
  metadata, schemas, channels and messages with their times and sequence numbers unchanged.
  The partial chunk at the end (at most the last flush period, 0.25 s) is what is lost.
* ``IN.can.log`` (candump): every complete line is copied; a last line cut in the middle is
  dropped.

Exit 0 when OUT was written (the input may also have been complete already: then OUT is an
identical copy of its content), 2 when IN cannot be read at all.
"""
from __future__ import annotations

import sys
from pathlib import Path

from mcap.records import Attachment, Channel, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from .mcap_reading import NotARecording, RecordingReader

PROG = "sharedctl record-recover"


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("record-recover",
                              help="rewrite a crashed recording (.mcap or .can.log) as a complete file")
    p.add_argument("input", metavar="IN", help="the .mcap (or .can.log) file a crashed recorder left")
    p.add_argument("output", metavar="OUT", help="where to write the complete file")
    p.set_defaults(handler=run)


def recover_mcap(source: Path, target: Path) -> dict:
    """Copy every complete record of ``source`` into a complete MCAP file ``target``."""
    reader = RecordingReader(source)
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    library = "sharedctl record-recover"
    with open(target, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        started = False
        for record in reader.records():
            if not started:
                writer.start(profile="", library=library)
                started = True
            if isinstance(record, Schema):
                schema_ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
            elif isinstance(record, Channel):
                channel_ids[record.id] = writer.register_channel(
                    record.topic, record.message_encoding, schema_ids.get(record.schema_id, 0), dict(record.metadata))
            elif isinstance(record, Metadata):
                writer.add_metadata(record.name, dict(record.metadata))
            elif isinstance(record, Attachment):
                writer.add_attachment(record.create_time, record.log_time, record.name, record.media_type, record.data)
            elif isinstance(record, Message) and record.channel_id in channel_ids:
                writer.add_message(channel_ids[record.channel_id], log_time=record.log_time, data=record.data,
                                   publish_time=record.publish_time, sequence=record.sequence)
        if not started:
            raise NotARecording(f"{source}: not an MCAP file ({reader.status.stopped_by})")
        writer.finish()
    status = reader.status
    return {"messages": status.messages, "channels": len(channel_ids), "was_complete": status.complete,
            "stopped_by": status.stopped_by}


def recover_can_log(source: Path, target: Path) -> dict:
    """Copy the complete lines of a candump log; drop a last line cut short."""
    data = source.read_bytes()
    cut = data.rfind(b"\n") + 1
    target.write_bytes(data[:cut])
    return {"lines": data[:cut].count(b"\n"), "dropped_bytes": len(data) - cut}


def run(args) -> int:
    source, target = Path(args.input), Path(args.output)
    if source.resolve() == target.resolve():
        print(f"{PROG}: OUT must differ from IN (IN is kept as it is)", file=sys.stderr)
        return 2
    try:
        if source.name.endswith(".log"):
            result = recover_can_log(source, target)
            dropped = f", a cut last line of {result['dropped_bytes']} bytes dropped" if result["dropped_bytes"] else ""
            print(f"{PROG}: {result['lines']} frames to {target}{dropped}")
            return 0
        result = recover_mcap(source, target)
    except (OSError, ValueError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    state = "was complete" if result["was_complete"] else f"ended early ({result['stopped_by']})"
    print(f"{PROG}: {result['messages']} messages on {result['channels']} channels to {target}; the input {state}")
    return 0
