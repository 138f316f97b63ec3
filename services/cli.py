"""`sharedctl` command line: one sub-command per module.

COMMANDS maps each sub-command's name to its module, which defines ``add_parser(subparsers)``:
it adds the sub-command and sets ``handler`` (a function taking the parsed args, returning an
exit code) with ``parser.set_defaults(handler=...)``. Only the module of the command being run
is imported (a robot or controller process does not pay for matplotlib); ``--help`` and an
unknown command import them all.

The processes need only the runtime dependencies; some studies need a module that comes with an
extra of pyproject.toml (EXTRAS). A command whose module, or whose run, finds that module missing
stops with a message naming the extra to install, and ``--help`` still lists every command. Any
other module that cannot be imported — one of this project's, or a runtime dependency — is a broken
installation: `main` says which, for which command, and exits 3 (never a silently shorter list).
"""
from __future__ import annotations

import argparse
import importlib
import importlib.metadata
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
    "foxglove": "sharedctl.services.foxglove.command",
}


# Top-level module -> the extra of pyproject.toml's [project.optional-dependencies] that brings it.
EXTRAS = {
    "matplotlib": "plots",
    "quadprog": "baselines",
    "dask": "montecarlo",
    "distributed": "montecarlo",
    "scipy": "montecarlo",
    "foxglove": "foxglove",
    "evdev": "gamepad",
    "rosbags": "ros2",
    "xxhash": "ros2",
}

# Options whose study imports an extra's module only when it gets there (at the end of a long
# run): checked before the command starts instead.
OPTION_NEEDS = {
    ("sim", "plot"): "matplotlib",
    ("compare", "report"): "matplotlib",
    ("faults", "report"): "matplotlib",
    ("controller", "ros2"): "rosbags",
    ("demo", "ros2"): "rosbags",
}


def missing_extra(exc: ModuleNotFoundError) -> str | None:
    """The extra that would provide the module `exc` did not find, if that module comes with one."""
    return EXTRAS.get((exc.name or "").partition(".")[0])


def extra_message(command: str, exc: ModuleNotFoundError) -> str:
    extra = missing_extra(exc)
    return (f"sharedctl {command}: needs {exc.name}, which comes with the '{extra}' extra: "
            f"pip install 'sharedctl[{extra}]'")


def _add_unavailable(subparsers, command: str, exc: ModuleNotFoundError) -> str:
    """List `command` in ``--help`` with the extra it needs; returns what `main` says if it is run."""
    subparsers.add_parser(command, add_help=False, help=f"(needs pip install 'sharedctl[{missing_extra(exc)}]')")
    return extra_message(command, exc)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of one sub-command (`command`, if it is a known name), else of all of them."""
    parser = argparse.ArgumentParser(
        prog="sharedctl",
        description="Shared-control teleoperation: simulation, services and tools.",
    )
    parser.add_argument("--version", action="version", version=f"sharedctl {version()}")
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    parser.unavailable = {}     # command -> why it cannot run here (its extra is not installed)
    modules = [COMMANDS[command]] if command in COMMANDS else list(dict.fromkeys(COMMANDS.values()))
    for module_name in modules:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if missing_extra(exc):
                for name in (n for n, m in COMMANDS.items() if m == module_name):
                    parser.unavailable[name] = _add_unavailable(subparsers, name, exc)
                continue
            raise IncompleteInstall(module_name, exc) from exc
        module.add_parser(subparsers)
    return parser


class IncompleteInstall(RuntimeError):
    """A module of this project (or a runtime dependency) that the installation lacks: a packaging mistake, said
    loudly instead of leaving the command out of the list."""

    def __init__(self, module_name: str, exc: ModuleNotFoundError) -> None:
        commands = ", ".join(n for n, m in COMMANDS.items() if m == module_name)
        super().__init__(f"this installation cannot import {exc.name!r} (needed by `sharedctl {commands}`, "
                         f"module {module_name}): reinstall sharedctl, or install its runtime dependencies")


def version() -> str:
    """The installed distribution's version (from its metadata; 'unknown' when run from a tree never installed)."""
    try:
        return importlib.metadata.version("sharedctl")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def main(argv: list[str] | None = None) -> int:
    from .service_config import ServiceConfigError, expand

    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        parser = build_parser(argv[0] if argv else None)
    except IncompleteInstall as exc:
        print(f"sharedctl: {exc}", file=sys.stderr)
        return 3
    if argv and argv[0] in parser.unavailable:
        print(parser.unavailable[argv[0]], file=sys.stderr)
        return 2
    try:
        argv = expand(argv, parser)   # --service-config FILE.toml
    except ServiceConfigError as exc:
        print(f"sharedctl: {exc}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    try:
        for (command, option), module in OPTION_NEEDS.items():
            value = getattr(args, option, None)
            if args.command == command and value is not None and value is not False and value != "":   # 0 is one
                importlib.import_module(module)
        return int(args.handler(args) or 0)
    except ModuleNotFoundError as exc:     # a study that imports its extra only when it gets there
        if not missing_extra(exc):
            raise
        print(extra_message(args.command, exc), file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
