"""`sharedctl` command line: one sub-command per module.

Each module named in COMMANDS defines ``add_parser(subparsers)``, which adds its
sub-command and sets ``handler`` (a function taking the parsed args, returning an
exit code) with ``parser.set_defaults(handler=...)``.
"""
from __future__ import annotations

import argparse
import importlib
import sys

COMMANDS = (
    "sharedctl.services.sim_command",
    "sharedctl.services.paper_command",
    "sharedctl.services.fuzz_command",
    "sharedctl.services.robot.command",
    "sharedctl.services.controller.command",
    "sharedctl.services.console.command",
    "sharedctl.services.demo_command",
    "sharedctl.services.bench.command",
    "sharedctl.services.compare_command",
    "sharedctl.services.faults.command",
    "sharedctl.services.security.router_command",
    "sharedctl.services.security.credentials_command",
    "sharedctl.services.faults.zenoh_relay",
    "sharedctl.services.faults.can_gateway",
    "sharedctl.services.recording.record_command",
    "sharedctl.services.recording.recover_command",
    "sharedctl.services.recording.replay_command",
    "sharedctl.services.recording.plot_command",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sharedctl",
        description="Shared-control teleoperation: simulation, services and tools.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module_name in COMMANDS:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:  # a command not built yet must not break the others
            if exc.name is None or not module_name.startswith(exc.name):
                raise
            continue
        module.add_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    from .service_config import ServiceConfigError, expand

    parser = build_parser()
    try:
        argv = expand(list(sys.argv[1:] if argv is None else argv), parser)   # --service-config FILE.toml
    except ServiceConfigError as exc:
        print(f"sharedctl: {exc}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    return int(args.handler(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
