"""`sharedctl fault-relay` — a Zenoh relay that impairs the operator and telemetry streams.

Zenoh peers do not forward between the peers they connect to, so the relay sits in the only
path between the console and the controller with two sessions:

    console ──connects──▶ F  [relay session "console side": listens on F]
                              [relay session "controller side": connects to C] ──▶ C controller

* operator direction (console → controller): ``…/operator/cmd`` and any ``…/alive/*`` the
  console side hears, through the ``operator.*`` pipeline; the lease query ``…/control/lease``
  is forwarded transparently (a queryable on F that asks C and relays every reply).
* telemetry direction (controller → console): ``…/state``, ``…/events`` and ``…/alive/*``
  through the ``telemetry.*`` pipeline.

Attachments travel with their payloads (an operator's signature, protocol/README.md §2.6): a
message the pipeline delays, duplicates or replays keeps its own, a corrupted one keeps the
original's (so a controller that verifies refuses it as `bad_signature`).

Behind the ``--secure`` router each side is a client of a router instead (``--console-config``,
``--controller-config``: Zenoh configuration files): the console's own router on one side, as the
controller role (which receives operator commands and answers lease queries there); the site
router on the other, as the console's operator (which may put its commands and ask for the lease):

    console ─▶ console router ◀─ relay (controller role) · relay (the operator) ─▶ site router ◀─ controller

Liveliness tokens are not mirrored (no process of this project watches them through the relay
today); the periodic ``alive`` heartbeats are.

Each session subscribes with ``allowed_origin=REMOTE`` and only republishes on the *other*
session, so the relay never hears its own publications. The ground-truth stream and the
demo's own measurements do not pass through the relay.

Faults are armed at the run's start: SIGUSR1 (sent by `sharedctl demo` once it has heard from the
controller that the operator holds control), or at once without ``--arm-on-signal``. Until then
messages pass unimpaired, so every run starts the same way. Arrival times given to the pipeline
are seconds from the run's t = 0: the instant the operator was granted the lease, which the demo
writes (wall-clock seconds) to ``--origin-file`` before it signals (without one, the arming is
t = 0). Timed windows (blackouts) thus open on the run's own clock, not when the demo heard of
it. A scheduler thread releases each message at its release time.

At exit (SIGTERM/SIGINT) the counters are written as JSON (``--stats FILE``): per direction the
pipeline's counters (received, lost, burst_lost, blackout_dropped, duplicated, corrupted,
bits_flipped, replayed, delayed, held_back, rate_dropped…) and what was measured at delivery
(delivered, out_of_order, latency_ms mean/max of the delay actually added).
"""
from __future__ import annotations

import heapq
import itertools
import json
import signal
import sys
import threading
import time
from pathlib import Path

import zenoh

from sharedctl.protocol import keys

from .. import zenoh_qos
from ..lifecycle import StopFlag
from ..security.zenoh_config import ZenohConfigError, open_from_file
from ..zenoh_session import EndpointError, check_loopback, open_session
from .impairments import Pipeline
from .spec import FaultSpecError, parse, pipeline

QUERY_TIMEOUT = 2.0     # s a forwarded lease query waits for the controller
ATTACHMENTS_KEPT = 512  # payloads whose attachment is remembered (a replayed or duplicated payload keeps its own)
MAX_ORIGIN_AGE = 5.0    # s: an origin further back than this (or in the future) is not this run's; arming is t = 0


def origin_monotonic(path: str | None) -> float:
    """The run's t = 0 on this process's monotonic clock: the wall-clock instant in `path` (a JSON
    ``{"lease_wall": S}`` written by the demo before it arms), else now. Same host, one clock pair."""
    now = time.monotonic()
    if not path:
        return now
    try:
        wall = float(json.loads(Path(path).read_text())["lease_wall"])
    except (OSError, ValueError, KeyError, TypeError):
        return now
    age = time.time() - wall
    return now - age if 0.0 <= age <= MAX_ORIGIN_AGE else now


class Direction:
    """One direction of the relay: its pipeline and what was measured at delivery."""

    def __init__(self, name: str, pipe: Pipeline) -> None:
        self.name, self.pipe = name, pipe
        self.passed_unarmed = 0
        self.delivered = 0
        self.out_of_order = 0
        self.publish_errors = 0
        self.max_seq = -1
        self.latency_sum = 0.0
        self.latency_max = 0.0
        self.latency_n = 0

    def report(self) -> dict:
        out = dict(self.pipe.counters)
        out.update(stages=self.pipe.describe(), passed_before_arming=self.passed_unarmed, delivered=self.delivered,
                   out_of_order=self.out_of_order, publish_errors=self.publish_errors,
                   latency_ms_mean=1000.0 * self.latency_sum / self.latency_n if self.latency_n else None,
                   latency_ms_max=1000.0 * self.latency_max if self.latency_n else None)
        return out


class ZenohRelay:
    """Two sessions and a release scheduler; `start()`, `arm()`, `stop()`, `report()`."""

    def __init__(self, listen: str | None, connect: str | None, robot: str, operator: Pipeline, telemetry: Pipeline,
                 console_config: str | None = None, controller_config: str | None = None) -> None:
        if (listen is None) == (console_config is None) or (connect is None) == (controller_config is None):
            raise ValueError("each side needs an endpoint or a Zenoh configuration file, not both")
        self.listen = None if listen is None else check_loopback(listen)
        self.connect = None if connect is None else check_loopback(connect)
        self.robot = robot
        self.configs = {"console": console_config, "controller": controller_config}
        self.attachments: dict[bytes, bytes] = {}   # payload -> its attachment, the last ATTACHMENTS_KEPT
        self.directions = {"operator": Direction("operator", operator), "telemetry": Direction("telemetry", telemetry)}
        self.cond = threading.Condition()
        self.heap: list = []
        self.order = itertools.count()
        self.seq = {"operator": itertools.count(), "telemetry": itertools.count()}
        self.t0: float | None = None
        self.armed_late: float | None = None      # s after t = 0 the faults were armed
        self.running = False
        self.sessions: dict[str, zenoh.Session] = {}
        self.entities: list = []
        self.publishers: dict = {}
        self.queries = {"forwarded": 0, "replies": 0, "errors": 0}
        self.thread: threading.Thread | None = None

    # ----- set-up ------------------------------------------------------------
    def start(self) -> "ZenohRelay":
        console_side = self.sessions["console"] = (open_from_file(self.configs["console"]) if self.configs["console"]
                                                   else open_session(listen=[self.listen]))
        controller_side = self.sessions["controller"] = (
            open_from_file(self.configs["controller"]) if self.configs["controller"]
            else open_session(connect=[self.connect]))
        remote = zenoh.Locality.REMOTE
        prefix = f"{keys.PREFIX}/{self.robot}"
        self.entities = [
            console_side.declare_subscriber(keys.operator_cmd_key(self.robot),
                                            lambda s: self._on_sample("operator", s), allowed_origin=remote),
            console_side.declare_subscriber(keys.alive_pattern(self.robot),
                                            lambda s: self._on_sample("operator", s), allowed_origin=remote),
            console_side.declare_queryable(f"{prefix}/control/lease", self._on_query, allowed_origin=remote),
            controller_side.declare_subscriber(keys.state_key(self.robot),
                                               lambda s: self._on_sample("telemetry", s), allowed_origin=remote),
            controller_side.declare_subscriber(keys.events_key(self.robot),
                                               lambda s: self._on_sample("telemetry", s), allowed_origin=remote),
            controller_side.declare_subscriber(keys.alive_pattern(self.robot),
                                               lambda s: self._on_sample("telemetry", s), allowed_origin=remote),
        ]
        self.running = True
        self.thread = threading.Thread(target=self._release_loop, name="relay-release", daemon=True)
        self.thread.start()
        return self

    def arm(self, origin: float | None = None) -> None:
        """Faults act from now on; `origin` (monotonic, default now) is the run's t = 0."""
        with self.cond:
            if self.t0 is None:
                now = time.monotonic()
                self.t0 = now if origin is None else min(origin, now)
                self.armed_late = now - self.t0

    def stop(self) -> None:
        with self.cond:
            self.running = False
            self.cond.notify_all()
        if self.thread is not None:
            self.thread.join(2.0)
        for entity in self.entities:
            try:
                entity.undeclare()
            except Exception:  # noqa: BLE001 — best effort at exit
                pass
        for session in self.sessions.values():
            session.close()

    def report(self) -> dict:
        with self.cond:
            return {"kind": "zenoh-relay", "listen": self.listen, "connect": self.connect,
                    "through_routers": {side: path is not None for side, path in self.configs.items()},
                    "armed": self.t0 is not None,
                    "armed_late_s": self.armed_late,
                    "pending": len(self.heap), "queries": dict(self.queries),
                    **{name: d.report() for name, d in self.directions.items()}}

    # ----- the data path -------------------------------------------------------
    def _on_sample(self, direction: str, sample) -> None:
        key = str(sample.key_expr)
        payload = sample.payload.to_bytes()
        attachment = None if sample.attachment is None else sample.attachment.to_bytes()
        d = self.directions[direction]
        with self.cond:
            now = time.monotonic()
            seq = next(self.seq[direction])
            impaired = self.t0 is not None
            if attachment is not None:
                self.attachments[payload] = attachment
                if len(self.attachments) > ATTACHMENTS_KEPT:
                    del self.attachments[next(iter(self.attachments))]
            if not impaired:
                d.passed_unarmed += 1
                items = [(now, payload)]
            else:
                items = [(self.t0 + release, data) for release, data in d.pipe.feed(now - self.t0, payload)]
            for release, data in items:
                extra = self.attachments.get(data, attachment)      # a replayed payload carries its own
                heapq.heappush(self.heap, (release, next(self.order), direction, key, data, now, seq, impaired, extra))
            if items:
                self.cond.notify()

    def _release_loop(self) -> None:
        while True:
            with self.cond:
                while self.running and (not self.heap or self.heap[0][0] > time.monotonic()):
                    timeout = None if not self.heap else max(0.0, self.heap[0][0] - time.monotonic())
                    self.cond.wait(timeout)
                if not self.running:
                    return
                _, _, direction, key, data, arrival, seq, impaired, attachment = heapq.heappop(self.heap)
            self._publish(direction, key, data, arrival, seq, impaired, attachment)

    def _publish(self, direction: str, key: str, data: bytes, arrival: float, seq: int, impaired: bool,
                 attachment: bytes | None = None) -> None:
        """Send on the other session; the latency is measured only for messages the pipeline held (a
        message that arrived before arming passes at once, even when it arrived after the run's t = 0)."""
        d = self.directions[direction]
        session = self.sessions["controller" if direction == "operator" else "console"]
        try:
            pub = self.publishers.get(key)
            if pub is None:
                pub = self.publishers[key] = zenoh_qos.declare_publisher(session, key)   # the stream's own QoS
            pub.put(data, attachment=attachment)
        except Exception:  # noqa: BLE001 — a failed put is counted, never fatal
            d.publish_errors += 1
            return
        latency = time.monotonic() - arrival
        with self.cond:
            d.delivered += 1
            if seq < d.max_seq:
                d.out_of_order += 1
            d.max_seq = max(d.max_seq, seq)
            if impaired:
                d.latency_sum += latency
                d.latency_n += 1
                d.latency_max = max(d.latency_max, latency)

    def _on_query(self, query) -> None:
        threading.Thread(target=self._forward_query, args=(query,), name="relay-query", daemon=True).start()

    def _forward_query(self, query) -> None:
        """Ask the controller side the same query and hand every reply back (unimpaired)."""
        try:
            payload = query.payload.to_bytes() if query.payload is not None else None
            attachment = query.attachment.to_bytes() if query.attachment is not None else None
            replies = self.sessions["controller"].get(str(query.selector), payload=payload, attachment=attachment,
                                                      timeout=QUERY_TIMEOUT)
            with self.cond:
                self.queries["forwarded"] += 1
            for reply in replies:
                if reply.ok is not None:
                    query.reply(reply.ok.key_expr, reply.ok.payload.to_bytes())
                    with self.cond:
                        self.queries["replies"] += 1
                else:
                    query.reply_err(reply.err.payload.to_bytes())
        except Exception:  # noqa: BLE001 — a query that cannot be forwarded is counted
            with self.cond:
                self.queries["errors"] += 1
        finally:
            query.drop()


# ----- the command ---------------------------------------------------------------
def add_fault_arguments(p) -> None:
    p.add_argument("--fault", action="append", default=[], metavar="SPEC",
                   help="a fault, e.g. operator.delay_ms=300 (repeatable; see services/faults/spec.py)")
    p.add_argument("--fault-seed", type=int, default=None, metavar="N", help="seed of the impairments (default 0)")


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("fault-relay",
                              help="Zenoh relay that injects operator.*/telemetry.* faults (demo --fault)",
                              description="Zenoh relay between console (--listen) and controller (--connect) "
                                          "that impairs operator.* and telemetry.* streams.")
    console = p.add_mutually_exclusive_group(required=True)
    console.add_argument("--listen", metavar="ENDPOINT", help="where the console connects (tcp/127.0.0.1:PORT)")
    console.add_argument("--console-config", metavar="FILE",
                         help="instead: a Zenoh configuration of a client of the console's router (as the controller "
                              "role, behind --secure)")
    controller = p.add_mutually_exclusive_group(required=True)
    controller.add_argument("--connect", metavar="ENDPOINT", help="the controller's endpoint")
    controller.add_argument("--controller-config", metavar="FILE",
                            help="instead: a Zenoh configuration of a client of the controller's router (as the "
                                 "console's operator, behind --secure)")
    p.add_argument("--ready", metavar="FILE", help="touch FILE once both sessions are open and declared")
    p.add_argument("--robot-id", default="robot1")
    add_fault_arguments(p)
    p.add_argument("--arm-on-signal", action="store_true", help="faults act from SIGUSR1 on (default: from the start)")
    add_origin_argument(p)
    p.add_argument("--stats", metavar="FILE", help="write the counters as JSON here at exit (default: stdout)")
    p.add_argument("--duration", type=float, metavar="S", help="exit after S seconds (a backstop)")
    p.set_defaults(handler=run)


def add_origin_argument(p) -> None:
    p.add_argument("--origin-file", metavar="FILE",
                   help='with --arm-on-signal: on SIGUSR1 read the run\'s t = 0 from FILE ({"lease_wall": S}, '
                        "wall-clock s); timed windows count from it (default: from the signal)")


def write_stats(report: dict, path: str | None) -> None:
    text = json.dumps(report, indent=1, default=str)
    if path:
        tmp = Path(path).with_suffix(".tmp")
        tmp.write_text(text)
        tmp.replace(path)
    else:
        print(text)


def run(args) -> int:
    stop = StopFlag().install()
    try:
        plan = parse(args.fault, args.fault_seed)
        keys.check_robot_id(args.robot_id)
        relay = ZenohRelay(args.listen, args.connect, args.robot_id, pipeline(plan, "operator"),
                           pipeline(plan, "telemetry"), args.console_config, args.controller_config)
    except (FaultSpecError, EndpointError, ZenohConfigError, ValueError) as exc:
        print(f"sharedctl fault-relay: {exc}", file=sys.stderr)
        return 2
    signal.signal(signal.SIGUSR1, lambda *_: relay.arm(origin_monotonic(args.origin_file)))
    if not args.arm_on_signal:
        relay.arm()
    try:
        relay.start()
    except Exception as exc:  # noqa: BLE001 — ZenohConfigError, or zenoh.ZError: a router that refuses the relay
        print(f"sharedctl fault-relay: cannot open its sessions: {exc}", file=sys.stderr)
        relay.stop()
        return 1
    if args.ready:
        Path(args.ready).touch()
    deadline = None if args.duration is None else time.monotonic() + args.duration
    try:
        while not stop.stopped and (deadline is None or time.monotonic() < deadline):
            stop.wait(0.1)
    finally:
        report = relay.report()
        relay.stop()
        write_stats(report, args.stats)
    return 0
