"""`sharedctl router --config FILE [--listen EP]... [--duration S]` — a Zenoh router in Python.

zenohd is not installable from PyPI; a Python Zenoh session in router mode routes and enforces
the same things: user/password authentication (`transport/auth/usrpwd/dictionary_file`), TLS and
mutual TLS on `tls/` endpoints (`transport/link/tls`), and the access-control list
(`access_control`). The configuration file is JSON5 (deploy/zenoh/router.json5 is the annotated
example) and is held to the project's rules: loopback endpoints only, scouting off
(services/security/zenoh_config.py). Every sharedctl process then runs as a client of this
router (`--zenoh-config` with `mode: "client"`).

SIGINT/SIGTERM: the session is closed and the process exits 0.
"""
from __future__ import annotations

import json
import sys
import time

import zenoh

from ..lifecycle import StopFlag
from .zenoh_config import ZenohConfigError, from_file, mode_of

PROG = "sharedctl router"


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("router", help="run a Zenoh router (auth, TLS/mTLS, access control) from a config file")
    p.add_argument("--config", required=True, metavar="FILE", help="Zenoh JSON5 configuration with mode \"router\"")
    p.add_argument("--listen", metavar="EP", action="append",
                   help="loopback endpoint to listen on (repeatable; replaces the file's listen/endpoints)")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds (default: until SIGINT/SIGTERM)")
    p.set_defaults(handler=run)


def describe(cfg: zenoh.Config) -> str:
    """One line: endpoints, authentication, TLS and ACL as configured."""
    def get(key):
        try:
            return json.loads(cfg.get_json(key))
        except Exception:   # noqa: BLE001 — a key this Zenoh does not know
            return None
    listen = get("listen/endpoints") or []
    dictionary = get("transport/auth/usrpwd/dictionary_file")
    tls = "mTLS" if get("transport/link/tls/enable_mtls") else "TLS"
    acl = get("access_control") or {}
    parts = [f"listen {' '.join(listen) if isinstance(listen, list) else listen}",
             f"usrpwd {'on' if dictionary else 'off'}",
             f"{tls} {'on' if any(str(e).startswith('tls/') for e in listen) else 'off'}",
             (f"ACL on (default {acl.get('default_permission')}, {len(acl.get('rules') or [])} rules, "
              f"{len(acl.get('subjects') or [])} subjects)" if acl.get("enabled") else "ACL off")]
    return ", ".join(parts)


def run(args) -> int:
    stop = StopFlag().install()
    if args.duration is not None and not args.duration > 0:
        print(f"{PROG}: --duration must be positive", file=sys.stderr)
        return 2
    try:
        cfg = from_file(args.config, listen=args.listen)
        if mode_of(cfg) != "router":
            raise ZenohConfigError(f"{args.config}: mode is {mode_of(cfg)!r}; a router configuration says \"router\"")
    except ZenohConfigError as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    summary = describe(cfg)
    start = time.monotonic()
    try:
        session = zenoh.open(cfg)
    except Exception as exc:   # noqa: BLE001 — zenoh.ZError: port taken, unreadable certificate, ...
        print(f"{PROG}: cannot start: {exc}", file=sys.stderr)
        return 1
    try:
        print(f"{PROG}: {session.zid()} {summary}", flush=True)
        while not stop.stopped:
            if args.duration is not None and time.monotonic() - start >= args.duration:
                break
            stop.wait(0.2)
    finally:
        session.close()
    wall = time.monotonic() - start
    cpu = time.process_time()
    print(f"{PROG}: stopped after {wall:.1f} s; "
          f"cpu {cpu:.2f} s ({100 * cpu / max(wall, 1e-9):.0f}% of one core)", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    """`python -m sharedctl.services.security.router_command --config FILE`: the router alone, without
    importing every other sub-command (what a systemd unit or a container runs)."""
    import argparse

    parser = argparse.ArgumentParser(prog=PROG)
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["router", *(sys.argv[1:] if argv is None else argv)])
    return args.handler(args)


if __name__ == "__main__":
    sys.exit(main())
