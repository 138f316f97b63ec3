"""`sharedctl record --out DIR [--zenoh-listen EP]… [--zenoh-connect EP]… [--robot-id ID]
[--can-interface I --can-channel C --can-option k=v …] [--scenario S] [--seed N] [--duration S]`

A recorder on its own: records every message under ``sharedctl/v1/<robot>/**`` that reaches
its Zenoh session (peers do not forward: connect to every publisher, or let them connect to
you) and, when a CAN option is given, a candump log of that bus. Runs until SIGINT/SIGTERM or
``--duration``; then finishes both files and prints a one-line summary.
"""
from __future__ import annotations

import sys
import time

from sharedctl.protocol.errors import KeyExprError

from .. import can_bus, zenoh_session
from ..lifecycle import StopFlag
from .flight_recorder import FlightRecorder

PROG = "sharedctl record"


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("record", help="record a robot's Zenoh traffic (MCAP) and CAN bus (candump log)")
    p.add_argument("--out", metavar="DIR", required=True, help="directory for the .mcap and .can.log files")
    p.add_argument("--zenoh-listen", metavar="EP", action="append",
                   help="listen on this loopback endpoint (repeatable)")
    p.add_argument("--zenoh-connect", metavar="EP", action="append",
                   help="connect to this loopback endpoint (repeatable)")
    p.add_argument("--robot-id", default="robot1", help="robot id in the key expressions (default robot1)")
    can_bus.add_arguments(p)
    p.add_argument("--scenario", help="scenario file or packaged name, stored in the recording's metadata")
    p.add_argument("--seed", help="seed of the run, stored in the recording's metadata")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds (default: until SIGINT/SIGTERM)")
    p.set_defaults(handler=run)


def run(args) -> int:
    stop = StopFlag().install()
    listen, connect = list(args.zenoh_listen or []), list(args.zenoh_connect or [])
    try:
        if not listen and not connect:
            listen = [zenoh_session.DEFAULT_ENDPOINT]
        zenoh_session.config(listen, connect)
        spec = can_bus.spec_from_args(args) if (args.can_interface or args.can_channel or args.can_option) else None
        recorder = FlightRecorder(args.out, "record", args.robot_id, scenario=args.scenario,
                                  scenario_name=args.scenario, seed=args.seed, can_spec=spec)
    except (KeyExprError, ValueError, OSError) as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    session, failed = None, False
    try:
        session = zenoh_session.open_session(listen, connect)
        recorder.attach(session)
        print(f"{PROG}: {recorder.mcap_path}" + (f", {recorder.can_log_path}" if recorder.can_log_path else ""),
              flush=True)
        end = None if args.duration is None else time.monotonic() + args.duration
        while not stop.stopped and (end is None or time.monotonic() < end):
            stop.wait(0.1)
    except Exception as exc:  # noqa: BLE001 — report; the files are still finished below
        print(f"{PROG}: {type(exc).__name__}: {exc}", file=sys.stderr)
        failed = True
    finally:
        summary = recorder.close()
        if session is not None:
            session.close()
    print(f"{PROG}: {summary['messages']} messages on {len(summary['topics'])} topics, "
          f"{summary['undecoded']} undecoded, {summary['dropped']} dropped"
          + (f", {summary['can_frames']} CAN frames" if spec is not None else ""),
          flush=True)
    return 0 if summary["write_error"] is None and not failed else 1

