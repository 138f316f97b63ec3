"""`sharedctl replay FILE.mcap [--speed X] [--zenoh-listen EP]… [--zenoh-connect EP]… [--delay S]`

Re-publishes a recording's messages on their Zenoh keys with the recorded spacing (log time),
``--speed`` times faster (1 = real time), so a console can watch the run again::

    sharedctl replay run.mcap --zenoh-listen tcp/127.0.0.1:7447 &
    sharedctl console --zenoh-connect tcp/127.0.0.1:7447 --scenario paper_convex

Decoded messages are re-encoded from their JSON (the same MessagePack map, validated by the wire
codec again); payloads the recorder could not decode are re-published byte for byte on the key
they arrived on; the derived views (``sharedctl/view/…``: foxglove.Log, foxglove.SceneUpdate) never crossed
Zenoh and are not re-published. Never point a replay at a running controller: the recorded operator commands
would drive it (the replay publishes on its own endpoint; only peers that connect to it hear it).
"""
from __future__ import annotations

import base64
import sys
import time
from dataclasses import dataclass

import msgpack

from sharedctl.protocol.errors import ProtocolError
from sharedctl.protocol.msgpack_codec import decode_message

from .. import zenoh_qos, zenoh_session
from ..lifecycle import StopFlag
from .mcap_reading import NotARecording, RecordedMessage, RecordingReader, check_readable

PROG = "sharedctl replay"


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("replay", help="re-publish a recording's messages on Zenoh (real time or faster)")
    p.add_argument("file", metavar="FILE.mcap")
    p.add_argument("--speed", type=float, default=1.0, metavar="X", help="playback speed, 1 = real time (default 1)")
    p.add_argument("--zenoh-listen", metavar="EP", action="append",
                   help=f"listen on this loopback endpoint (repeatable; default {zenoh_session.DEFAULT_ENDPOINT})")
    p.add_argument("--zenoh-connect", metavar="EP", action="append",
                   help="connect to this loopback endpoint (repeatable)")
    p.add_argument("--delay", type=float, default=1.0, metavar="S",
                   help="wait this long after opening the session, for viewers to connect (default 1)")
    p.set_defaults(handler=run)


class ReplayError(ValueError):
    """A recorded message that cannot be turned back into a wire payload."""


def wire_payload(message: RecordedMessage) -> tuple[str, bytes]:
    """(key, payload) to publish for one recorded message; raises :class:`ReplayError`."""
    try:
        body = message.json()
    except ValueError as exc:
        raise ReplayError(f"{message.topic}: not JSON ({exc})") from None
    if message.undecoded:
        try:
            return str(body["key"]), base64.b64decode(body["payload_base64"], validate=True)
        except (KeyError, TypeError, ValueError) as exc:
            raise ReplayError(f"undecoded record without key/payload ({exc})") from None
    payload = msgpack.packb(body, use_bin_type=True, use_single_float=False)
    try:
        decode_message(payload, None)
    except ProtocolError as exc:
        raise ReplayError(f"{message.topic}: {type(exc).__name__}: {exc}") from None
    return message.topic, payload


@dataclass
class ReplayReport:
    published: int = 0
    skipped: int = 0
    views: int = 0              # derived views in the file, not re-published
    keys: int = 0
    recorded_seconds: float = 0.0
    wall_seconds: float = 0.0
    complete_file: bool = False
    stopped_by: str | None = None


def replay(path, session, speed: float = 1.0, stop: StopFlag | None = None) -> ReplayReport:
    """Publish every message of ``path`` on ``session`` with the recorded spacing divided by ``speed``."""
    if not speed > 0:
        raise ValueError("speed must be positive")
    stop = stop or StopFlag()
    reader = RecordingReader(path)
    publishers: dict[str, object] = {}
    report = ReplayReport()
    start_wall = time.monotonic()
    first_log = last_log = None
    try:
        for message in reader.messages():
            if stop.stopped:
                break
            if message.view:
                report.views += 1
                continue
            try:
                key, payload = wire_payload(message)
            except ReplayError:
                report.skipped += 1
                continue
            if first_log is None:
                first_log = message.log_time
            last_log = message.log_time
            delay = start_wall + (message.log_time - first_log) / 1e9 / speed - time.monotonic()
            if delay > 0 and stop.wait(delay):
                break
            publisher = publishers.get(key)
            if publisher is None:
                try:
                    # one QoS for every key (Zenoh's default): streams of different priorities would overtake
                    # one another, and a replay keeps the recorded order
                    publisher = publishers[key] = zenoh_qos.declare_publisher(session, key, zenoh_qos.DEFAULT)
                except Exception:  # noqa: BLE001 — a key Zenoh refuses (only possible for undecoded records)
                    report.skipped += 1
                    continue
            publisher.put(payload)
            report.published += 1
    finally:
        for publisher in publishers.values():
            publisher.undeclare()
    report.keys = len(publishers)
    report.recorded_seconds = 0.0 if first_log is None else (last_log - first_log) / 1e9
    report.wall_seconds = time.monotonic() - start_wall
    report.complete_file = reader.status.complete
    report.stopped_by = reader.status.stopped_by
    if not stop.stopped:
        check_readable(reader.status, path)
    return report


def run(args) -> int:
    stop = StopFlag().install()
    listen, connect = list(args.zenoh_listen or []), list(args.zenoh_connect or [])
    if not listen and not connect:
        listen = [zenoh_session.DEFAULT_ENDPOINT]
    try:
        if not args.speed > 0 or args.delay < 0:
            raise ValueError("--speed must be positive and --delay not negative")
        zenoh_session.config(listen, connect)
        with open(args.file, "rb"):
            pass
    except (ValueError, OSError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    session = zenoh_session.open_session(listen, connect)
    try:
        print(f"{PROG}: {args.file} at {args.speed:g}x on " + " ".join(listen + connect), flush=True)
        if stop.wait(args.delay):
            return 0
        report = replay(args.file, session, args.speed, stop)
    except NotARecording as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    finally:
        session.close()
    tail = "" if report.complete_file else f"; the file ends early ({report.stopped_by}): sharedctl record-recover"
    print(f"{PROG}: {report.published} messages on {report.keys} keys, {report.recorded_seconds:.1f} s recorded "
          f"in {report.wall_seconds:.1f} s, {report.skipped} skipped{tail}", flush=True)
    return 0
