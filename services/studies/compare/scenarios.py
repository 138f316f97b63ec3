"""The scenario set of `sharedctl compare`: packaged scenarios plus one derived non-convex adversarial case.

* adversarial-wall — sharedctl/scenarios/adversarial_wall.toml: an operator holding the stick at
  full deflection towards a point 1 m beyond the top face of the paper's convex set;
* paper-convex, paper-nonconvex — the paper's Section 5 scenarios with the scripted operator;
* adversarial-corner — the paper's non-convex set (x ≤ 0 or y ≤ 0) with the adversarial operator
  starting in both polytopes at (−1, −1.2) and driving diagonally at (0.6, 0.6), inside the
  obstacle: into the re-entrant corner, where a filter must choose which polytope to respect.

`--quick` shortens the long paper runs (the adversarial ones keep their full length).
"""
from __future__ import annotations

import copy
import tomllib
from dataclasses import dataclass
from importlib import resources

from sharedctl.scenario import Scenario, parse


@dataclass(frozen=True)
class Entry:
    scenario: Scenario
    duration: float
    source: str


QUICK_DURATION = {"paper-convex": 16.0, "paper-nonconvex": 10.0}   # s: past the first face contact


def _packaged(name: str) -> dict:
    return tomllib.loads(resources.files("sharedctl").joinpath(f"scenarios/{name}.toml").read_text("utf-8"))


def adversarial_corner() -> dict:
    data = copy.deepcopy(_packaged("paper_nonconvex"))
    data["name"] = "adversarial-corner"
    data["duration"] = 8.0
    data["initial"] = {"q": [-1.0, -1.2, 0.0], "qdot": [0.0, 0.0, 0.0]}
    data["desired"] = {"kind": "point", "at": [0.6, 0.6, 0.0]}
    data["human"] = {"kind": "adversarial", "kp": 20.0}
    return data


def scenario_set(quick: bool = False, duration: float | None = None) -> list[Entry]:
    """The comparison's scenarios, in report order; `duration` overrides every run's length (tests)."""
    sources = [
        ("sharedctl/scenarios/adversarial_wall.toml", _packaged("adversarial_wall")),
        ("sharedctl/scenarios/paper_convex.toml", _packaged("paper_convex")),
        ("sharedctl/scenarios/paper_nonconvex.toml", _packaged("paper_nonconvex")),
        ("paper_nonconvex.toml with the adversarial operator (services/studies/compare/scenarios.py)",
         adversarial_corner()),
    ]
    out = []
    for source, data in sources:
        sc = parse(data)
        length = duration or (QUICK_DURATION.get(sc.name, sc.duration) if quick else sc.duration)
        out.append(Entry(sc, min(length, sc.duration), source))
    return out
