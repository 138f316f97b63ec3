"""Paths and readers shared by the deploy-file tests."""
from __future__ import annotations

import re
import shlex
from pathlib import Path

import yaml

from sharedctl.services.cli import build_parser
from sharedctl.services.service_config import expand

ROOT = Path(__file__).resolve().parents[2]
DEPLOY = ROOT / "deploy"
DOC = ROOT / "docs" / "deploy.md"
UNITS = sorted((DEPLOY / "systemd").glob("*.service"))


def compose() -> dict:
    return yaml.safe_load((DEPLOY / "docker-compose.yml").read_text())


def locked_version(package: str) -> str:
    """The version requirements/runtime.lock (what the image installs) pins `package` to."""
    for line in (ROOT / "requirements" / "runtime.lock").read_text().splitlines():
        name, sep, rest = line.partition("==")
        if sep and name.strip().lower() == package.lower():
            return rest.split(";")[0].rstrip(" \\")
    raise AssertionError(f"{package} is not in requirements/runtime.lock")


def parse_command(argv: list[str]):
    """The argparse namespace a sharedctl command line (with --service-config expanded) gives."""
    parser = build_parser()
    return parser.parse_args(expand(list(argv), parser))


def unit_exec_start(unit: Path) -> list[str]:
    line = next(s for s in unit.read_text().splitlines() if s.startswith("ExecStart="))
    return shlex.split(line.split("=", 1)[1])


def unit_keys(unit: Path) -> dict[str, str]:
    keys = {}
    for line in unit.read_text().splitlines():
        m = re.match(r"^([A-Za-z]+)=(.*)$", line)
        if m:
            keys[m.group(1)] = m.group(2)
    return keys
