"""Reading scenario files from disk or from the packaged examples."""
from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

from sharedctl.scenario import Scenario, ScenarioError, parse

PACKAGED = tuple(sorted(entry.name.removesuffix(".toml")
                        for entry in resources.files("sharedctl.scenarios").iterdir()
                        if entry.name.endswith(".toml")))


def load(path_or_name: str) -> Scenario:
    """A TOML path, or the name of a packaged scenario (`paper_convex` or `paper_convex.toml`); a file of that
    name in the working directory wins."""
    path = Path(path_or_name)
    name = path_or_name.removesuffix(".toml")          # a packaged one by its name or its file name
    if path.exists():
        data = path.read_bytes()
    elif name in PACKAGED:
        data = resources.files("sharedctl.scenarios").joinpath(f"{name}.toml").read_bytes()
    else:
        raise ScenarioError(f"no scenario file {path_or_name!r} (packaged: {', '.join(PACKAGED)})")
    try:
        return parse(tomllib.loads(data.decode("utf-8")))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path_or_name}: not valid TOML: {exc}") from None
