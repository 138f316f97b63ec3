"""`sharedctl` command line: one sub-command per module.

COMMANDS maps each sub-command's name to its module, which defines ``add_parser(subparsers)``:
it adds the sub-command and sets ``handler`` (a function taking the parsed args, returning an
exit code) with ``parser.set_defaults(handler=...)``. Only the module of the command being run
is imported (a robot or controller process does not pay for matplotlib); ``--help`` and an
unknown command import them all.
"""
from __future__ import annotations

import argparse
import importlib
import sys

COMMANDS = {
    "sim": "sharedctl.services.studies.sim.command",
    "paper": "sharedctl.services.studies.paper.command",
    "fuzz": "sharedctl.services.studies.fuzz.command",
    "robot": "sharedctl.services.robot.command",
    "controller": "sharedctl.services.controller.command",
    "console": "sharedctl.services.console.command",
    "demo": "sharedctl.services.demo.command",
    "bench": "sharedctl.services.studies.bench.command",
    "compare": "sharedctl.services.studies.compare.command",
    "faults": "sharedctl.services.studies.campaign.command",
    "router": "sharedctl.services.security.router_command",
    "credentials": "sharedctl.services.security.credentials_command",
    "fault-relay": "sharedctl.services.faults.zenoh_relay",
    "fault-gateway": "sharedctl.services.faults.can_gateway",
    "record": "sharedctl.services.recording.record_command",
    "record-recover": "sharedctl.services.recording.recover_command",
    "replay": "sharedctl.services.recording.replay_command",
    "plot": "sharedctl.services.studies.plot.command",
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of one sub-command (`command`, if it is a known name), else of all of them."""
    parser = argparse.ArgumentParser(
        prog="sharedctl",
        description="Shared-control teleoperation: simulation, services and tools.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    modules = [COMMANDS[command]] if command in COMMANDS else list(dict.fromkeys(COMMANDS.values()))
    for module_name in modules:
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

    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(argv[0] if argv else None)
    try:
        argv = expand(argv, parser)   # --service-config FILE.toml
    except ServiceConfigError as exc:
        print(f"sharedctl: {exc}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    return int(args.handler(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
