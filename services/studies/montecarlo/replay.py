"""Counterexamples of the Monte-Carlo replayed once in the real processes.

Each counterexample is rebuilt from its chunk (the seed and the chunk's index decide every draw, so
the scenario file carries the run's own set, start, operator and law), written as a scenario file,
and run as `sharedctl demo --scenario FILE --fault …` for the Monte-Carlo's duration (the campaign's
runner: services/studies/campaign/matrix.py), judged on the simulator's ground truth. The outcome
sits beside the model's in the JSON and the report.
"""
from __future__ import annotations

from pathlib import Path

from ..campaign.matrix import Case, subprocess_runner
from .cases import build, fault_specs, scenario_data
from .executor import Chunk, chunk_rng
from .report import scenario_toml


def rebuild(run: int, runs: int, seed: int, chunk_runs: int, families: tuple,
            brake_torque: float | None = None) -> tuple[dict, list[str]]:
    """(scenario mapping, --fault specs) of run `run` of a Monte-Carlo of `runs` runs: its chunk drawn again."""
    index = run // chunk_runs
    first = index * chunk_runs
    chunk = Chunk(index, first, min(chunk_runs, runs - first), seed)
    case = build(index, chunk.runs, chunk_rng(chunk), families)
    i, d = run - first, case.draws
    return (scenario_data(case.regions, d["q0"][:, i], d["target"][:, i], d["kp"][i], case.law, d["deflection"][i],
                          brake_torque), fault_specs(case, i))


def replay(counterexamples: list[dict], workdir: Path, duration: float, limit: int, plan: dict) -> list[dict]:
    """Up to `limit` counterexamples, in order; one row per replay. `plan`: the Monte-Carlo's runs, seed,
    chunk_runs, families and brake_torque (the command's), to draw each counterexample's case again."""
    workdir.mkdir(parents=True, exist_ok=True)
    runner = subprocess_runner(workdir)
    rows = []
    for i, example in enumerate(counterexamples[:limit]):
        data, faults = rebuild(example["run"], plan["runs"], plan["seed"], plan["chunk_runs"], tuple(plan["families"]),
                               plan.get("brake_torque"))
        assert faults == example["faults"], (faults, example["faults"])      # the same draw
        scenario = workdir / f"run-{example['run']}.toml"
        scenario.write_text(scenario_toml(data, example["faults"]))
        case = Case(str(scenario), tuple(example["faults"]), duration, example["law"])
        result = runner(case, i)
        summary = result.summary or {}
        rows.append({"run": example["run"], "family": example["family"], "law": example["law"],
                     "faults": example["faults"], "model_min_margin": example["min_margin"],
                     "real_min_margin": summary.get("min_margin"), "real_violations": summary.get("violations"),
                     "real_estops": summary.get("estops"), "exit_code": result.exit_code,
                     "error": result.error or summary.get("failure")})
    return rows
