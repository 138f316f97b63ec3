"""`sharedctl foxglove --connect EP [--connect EP …] [--zenoh-listen EP …] [--listen HOST:PORT] [--scenario S]
[--robot-id ID] [--allow-remote] [--duration S] [--json OUT] [--write-layout FILE]` — the live view: a Foxglove
WebSocket server fed from Zenoh.

Subscribes to ``sharedctl/v1/<robot>/**`` on every endpoint it connects to (Zenoh peers do not
forward for each other: connect to each publisher whose data you want, or have it connect to
``--zenoh-listen``) and serves, on a foxglove-sdk WebSocket server at ``--listen`` (default
127.0.0.1:8765), the channels a recording holds (:mod:`.bridge`): every message as JSON on its
key with the schema of its kind, ``foxglove.Log`` for the events, ``foxglove.SceneUpdate`` for the
admissible set of ``--scenario`` at the robot's heading, the robot, its reference and the
operator's wish. A non-loopback ``--listen`` host is refused without ``--allow-remote``.

The Zenoh callback only reads the clock and queues; one thread converts and hands each record to
the SDK. Malformed payloads are published as ``sharedctl.Undecoded`` and counted; a record that
cannot be made is counted; each is said once on stderr. SIGINT/SIGTERM: the subscriber undeclared,
the session closed, the queue drained, the server stopped, exit 0.
"""
from __future__ import annotations

import queue
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import foxglove

from sharedctl.protocol import keys
from sharedctl.scenario import ScenarioError

from .. import zenoh_session
from ..lifecycle import StopFlag
from ..recording.json_form import JsonRecord, wire_record, zenoh_time_ns
from ..recording.json_schemas import MESSAGE_ENCODING, SCHEMA_ENCODING, UNDECODED_TOPIC, schema_bytes
from ..recording.scene import DEFAULT_HALF_WIDTH
from ..recording.views import views_for
from ..summary_output import write_json
from .address import listen_address
from .bridge import LiveView
from .layout import layout_json

PROG = "sharedctl foxglove"
DEFAULT_LISTEN = "127.0.0.1:8765"
MAX_QUEUED = 10_000          # samples waiting for the publisher thread; beyond this they are counted as dropped
_STOP = object()


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("foxglove", help="live view: serve the robot's Zenoh traffic to Foxglove over WebSocket")
    p.add_argument("--connect", metavar="EP", action="append", default=[],
                   help="Zenoh endpoint to connect to (loopback tcp/…; repeatable: every publisher's, "
                        "e.g. the controller's and the robot's)")
    p.add_argument("--zenoh-listen", metavar="EP", action="append", default=[],
                   help="Zenoh endpoint publishers may connect to (loopback tcp/…; repeatable)")
    p.add_argument("--listen", default=DEFAULT_LISTEN, metavar="HOST:PORT",
                   help=f"WebSocket address (default {DEFAULT_LISTEN}; port 0: a free one)")
    p.add_argument("--allow-remote", action="store_true",
                   help="allow a --listen host that is not loopback (the server has no authentication)")
    p.add_argument("--scenario", default="paper_convex",
                   help="scenario whose admissible set the scene draws (file or packaged name; default paper_convex)")
    p.add_argument("--robot-id", default="robot1", help="robot id in the key expressions (default robot1)")
    p.add_argument("--view-half-width", type=float, default=DEFAULT_HALF_WIDTH, metavar="M",
                   help="half-width of the square around the robot the set is drawn in "
                        f"(default {DEFAULT_HALF_WIDTH} m)")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds (default: until SIGINT/SIGTERM)")
    p.add_argument("--json", metavar="OUT", help="at exit, write what was served (messages per topic, counts) as JSON")
    p.add_argument("--write-layout", metavar="FILE",
                   help="write the Foxglove layout for --robot-id's channels to FILE and exit "
                        "(deploy/foxglove/sharedctl-layout.json is robot1's)")
    p.set_defaults(handler=run)


@dataclass
class ServedCounts:
    """What the live view did, for its exit summary."""

    messages: int = 0
    undecoded: int = 0
    errors: int = 0             # samples whose records could not be made or handed to the SDK
    dropped: int = 0            # the queue was full
    per_topic: dict[str, int] = field(default_factory=dict)
    first_error: str | None = None


class Publisher:
    """Zenoh samples in (any thread), SDK channels out (one thread)."""

    def __init__(self, view: LiveView, context: foxglove.Context) -> None:
        self.view = view
        self.context = context
        self.counts = ServedCounts()
        self._channels: dict[tuple[str, str], foxglove.Channel] = {}
        self._said: set[str] = set()
        for topic, kind, schema in view.known_channels():
            self._channel(topic, kind, schema)
        self._queue: queue.Queue = queue.Queue(MAX_QUEUED)
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="foxglove-publisher", daemon=True)
        self._thread.start()

    def on_sample(self, sample) -> None:
        """Zenoh subscriber callback: the clock and a queue put, nothing else."""
        self.put(str(sample.key_expr), sample.payload.to_bytes(), time.time_ns(), zenoh_time_ns(sample.timestamp))

    def put(self, key: str, payload: bytes, log_ns: int, publish_ns: int | None = None) -> None:
        if self._closed:
            return
        try:
            self._queue.put_nowait((key, payload, log_ns, publish_ns))
        except queue.Full:
            self.counts.dropped += 1

    def close(self, timeout: float = 2.0) -> ServedCounts:
        if not self._closed:
            self._closed = True
            self._queue.put(_STOP)
            self._thread.join(timeout)
            for channel in self._channels.values():
                channel.close()
        return self.counts

    def _run(self) -> None:
        while (item := self._queue.get()) is not _STOP:
            self.publish(*item)

    def publish(self, key: str, payload: bytes, log_ns: int, publish_ns: int | None) -> None:
        """The sample as recorded, then what is derived from it; a failure of either is counted and said once."""
        record = wire_record(key, payload, log_ns, publish_ns)
        try:
            self._log(record)
            for derived in self.view.derive(record):
                self._log(derived)
        except Exception as exc:  # noqa: BLE001 — a record that cannot be made or served must not stop the view
            self.counts.errors += 1
            self.counts.first_error = self.counts.first_error or f"{key}: {type(exc).__name__}: {exc}"
            self._say_once("error", f"cannot serve a message on {key}: {type(exc).__name__}: {exc} "
                                    "(counted; said once)")

    def _log(self, record: JsonRecord) -> None:
        if record.topic == UNDECODED_TOPIC:
            self.counts.undecoded += 1
            self._say_once("undecoded", f"a payload the wire codec refuses ({record.data[:200]!r}): served on "
                                        f"{UNDECODED_TOPIC} and counted (said once)")
        self._channel(record.topic, record.kind, record.schema).log(record.data, log_time=record.log_time)
        self.counts.messages += 1
        self.counts.per_topic[record.topic] = self.counts.per_topic.get(record.topic, 0) + 1

    def _channel(self, topic: str, kind: str, schema: dict) -> foxglove.Channel:
        channel = self._channels.get((topic, kind))
        if channel is None:
            body = foxglove.Schema(name=schema["title"], encoding=SCHEMA_ENCODING, data=schema_bytes(schema))
            channel = self._channels[(topic, kind)] = foxglove.Channel(
                topic, schema=body, message_encoding=MESSAGE_ENCODING, context=self.context, metadata={"kind": kind})
        return channel

    def _say_once(self, what: str, text: str) -> None:
        if what not in self._said:
            self._said.add(what)
            print(f"{PROG}: {text}", file=sys.stderr, flush=True)


def write_layout(path: str, robot: str) -> int:
    try:
        keys.check_robot_id(robot)
        Path(path).write_text(layout_json(robot), encoding="utf-8")
    except (ValueError, OSError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    print(f"{PROG}: layout for {robot} written to {path}")
    return 0


def run(args) -> int:
    if args.write_layout:
        return write_layout(args.write_layout, args.robot_id)
    try:
        host, port = listen_address(args.listen, args.allow_remote)
        if not args.connect and not args.zenoh_listen:
            raise ValueError("give at least one --connect (or --zenoh-listen) endpoint")
        zenoh_session.config(args.zenoh_listen, args.connect)        # loopback endpoints only
        keys.check_robot_id(args.robot_id)
        if not args.view_half_width > 0:
            raise ValueError("--view-half-width must be positive")
        if args.duration is not None and not args.duration > 0:
            raise ValueError("--duration must be positive")
        view = LiveView(views_for(args.robot_id, args.scenario, args.view_half_width))
    except (ValueError, ScenarioError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    stop = StopFlag().install()
    context = foxglove.Context()
    try:
        server = foxglove.start_server(name=f"sharedctl {args.robot_id}", host=host, port=port, context=context)
    except Exception as exc:  # noqa: BLE001 — the SDK's error type for a busy or forbidden address
        print(f"{PROG}: cannot serve on {args.listen}: {exc}", file=sys.stderr)
        return 1
    served = f"{host}:{server.port}"
    publisher = Publisher(view, context)
    session = subscriber = None
    try:
        session = zenoh_session.open_session(args.zenoh_listen, args.connect)
        subscriber = session.declare_subscriber(keys.robot_pattern(args.robot_id), publisher.on_sample)
        print(f"{PROG}: ws://{served} ← {' '.join(args.connect + args.zenoh_listen)} "
              f"({args.robot_id}, scenario {args.scenario})", flush=True)
        deadline = None if args.duration is None else time.monotonic() + args.duration
        while not stop.wait(0.2):
            if deadline is not None and time.monotonic() >= deadline:
                break
    finally:
        if subscriber is not None:
            subscriber.undeclare()
        if session is not None:
            session.close()
        counts = publisher.close()
        server.stop()
    print(f"{PROG}: {counts.messages} messages on {len(counts.per_topic)} topics served "
          f"({counts.undecoded} undecoded, {counts.errors} errors, {counts.dropped} dropped)", flush=True)
    if args.json:
        write_json(args.json, {"listen": served, "connect": args.connect,
                               "zenoh_listen": args.zenoh_listen, "scenario": args.scenario,
                               "messages": counts.messages, "topics": dict(sorted(counts.per_topic.items())),
                               "undecoded": counts.undecoded, "errors": counts.errors, "dropped": counts.dropped,
                               "first_error": counts.first_error})
    return 0
