"""Reading scenario files from disk or from the packaged examples."""
from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

from sharedctl.scenario import Scenario, ScenarioError, parse

PACKAGED = tuple(sorted(entry.name.removesuffix(".toml")
                        for entry in resources.files("sharedctl").joinpath("scenarios").iterdir()
                        if entry.name.endswith(".toml")))


def load(path_or_name: str) -> Scenario:
    """A TOML path, or the name of a packaged scenario (e.g. `paper_convex`)."""
    path = Path(path_or_name)
    if path.exists():
        data = path.read_bytes()
    elif path_or_name in PACKAGED:
        data = resources.files("sharedctl").joinpath(f"scenarios/{path_or_name}.toml").read_bytes()
    else:
        raise ScenarioError(f"no scenario file {path_or_name!r} (packaged: {', '.join(PACKAGED)})")
    try:
        return parse(tomllib.loads(data.decode("utf-8")))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path_or_name}: not valid TOML: {exc}") from None
