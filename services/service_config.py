"""Service settings from a TOML file: `sharedctl COMMAND --service-config FILE.toml [options…]`.

A site keeps each process's options in a file (deploy/config/*.toml) instead of a long command
line in a unit file. The file is a flat TOML table whose keys are the command's long options
without the dashes; its values become those options, placed *before* the ones given on the
command line, so an explicit option wins: a file's setting of an option the command line gives
again is left out (for a repeatable option, both are used), and so is one that belongs to a
mutually exclusive group another of whose options the command line gives (`console
--service-config console.toml --script X` drops the file's `scenario`):

    scenario = "paper_convex"          →  --scenario paper_convex
    can-option = ["port=7500"]         →  --can-option port=7500      (a list repeats the option)
    quiet = true                       →  --quiet                     (false: left out)

Checked once, before anything starts: a key the command does not have, a nested table, or a
value that is not a string, number, boolean or list of those is a `ServiceConfigError` naming
the file and the key.
"""
from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

OPTION = "--service-config"


class ServiceConfigError(ValueError):
    """A settings file that cannot be used (unreadable, bad TOML, unknown key, bad value)."""


def _subparser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser | None:
    for action in parser._actions:                      # noqa: SLF001 — argparse has no public accessor
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001 — nor a public class for sub-commands
            return action.choices.get(command)
    return None


def _scalar(value, path: Path, key: str) -> str:
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        raise ServiceConfigError(f"{path}: {key}: expected a string or a number, got {type(value).__name__}")
    return str(value)


def options_from_file(path: Path, known: dict[str, argparse.Action]) -> list[str]:
    """The command-line options a settings file stands for (`known`: the command's option strings)."""
    return [token for _, tokens in _settings(path, known) for token in tokens]


def _settings(path: Path, known: dict[str, argparse.Action]) -> list[tuple[argparse.Action, list[str]]]:
    """Each key of a settings file as (its option's action, the command-line tokens it stands for)."""
    try:
        table = tomllib.loads(path.read_text())
    except OSError as exc:
        raise ServiceConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ServiceConfigError(f"{path}: not valid TOML: {exc}") from None
    settings: list[tuple[argparse.Action, list[str]]] = []
    for key, value in table.items():
        option = f"--{key}"
        action = known.get(option)
        if action is None or option == OPTION:
            raise ServiceConfigError(f"{path}: unknown key {key!r} (not an option of this command)")
        if isinstance(value, dict):
            raise ServiceConfigError(f"{path}: {key}: nested tables are not settings")
        if action.nargs == 0:                           # a flag
            if not isinstance(value, bool):
                raise ServiceConfigError(f"{path}: {key}: expected true or false")
            negative = f"--no-{key}"                    # argparse.BooleanOptionalAction: false → --no-KEY
            tokens = [option] if value else ([negative] if negative in action.option_strings else [])
        elif isinstance(value, list):
            tokens = [t for item in value for t in (option, _scalar(item, path, key))]
        else:
            tokens = [option, _scalar(value, path, key)]
        settings.append((action, tokens))
    return settings


def _given(argv: list[str], known: dict[str, argparse.Action]) -> set[argparse.Action]:
    """The actions whose options appear in `argv` (`--opt value` or `--opt=value`)."""
    return {known[a.split("=", 1)[0]] for a in argv if a.startswith("--") and a.split("=", 1)[0] in known}


def _overruled(action: argparse.Action, given: set[argparse.Action], sub: argparse.ArgumentParser) -> bool:
    """A file's setting that the command line replaces: the same option, or another of its mutually exclusive
    group (`--script` on the command line overrules the file's `scenario`, which may not be given with it)."""
    if action in given and action.nargs != 0 and not isinstance(action, argparse._AppendAction):  # noqa: SLF001
        return True
    return any(action in group._group_actions and given & set(group._group_actions) - {action}   # noqa: SLF001
               for group in sub._mutually_exclusive_groups)   # noqa: SLF001 — argparse keeps them private


def expand(argv: list[str], parser: argparse.ArgumentParser) -> list[str]:
    """`argv` with `--service-config FILE` replaced by the file's options (right after the command name)."""
    if not argv or not any(a == OPTION or a.startswith(OPTION + "=") for a in argv[1:]):
        return list(argv)
    command, rest = argv[0], list(argv[1:])
    sub = _subparser(parser, command)
    if sub is None:
        raise ServiceConfigError(f"{OPTION} is not an option of {command!r}")
    files, remaining = [], []
    i = 0
    while i < len(rest):
        arg = rest[i]
        if arg == OPTION:
            if i + 1 >= len(rest):
                raise ServiceConfigError(f"{OPTION} needs a FILE")
            files.append(rest[i + 1])
            i += 2
            continue
        if arg.startswith(OPTION + "="):
            files.append(arg.split("=", 1)[1])
        else:
            remaining.append(arg)
        i += 1
    known = sub._option_string_actions   # noqa: SLF001 — argparse's option table
    given = _given(remaining, known)
    from_files = [token for name in files for action, tokens in _settings(Path(name), known)
                  if not _overruled(action, given, sub) for token in tokens]
    return [command, *from_files, *remaining]


def add_argument(p: argparse.ArgumentParser) -> None:
    """Declare the option so `--help` lists it (the file is read by `expand` before parsing)."""
    p.add_argument(OPTION, metavar="FILE.toml",
                   help="read options from this TOML file first (keys are long option names; deploy/config/)")
