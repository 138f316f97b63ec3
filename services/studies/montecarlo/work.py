"""One chunk of the Monte-Carlo (`run_chunk`, the task the executor maps) and the summary of all.

A chunk draws its case from its own generator (executor.chunk_rng: the seed and the chunk's
index, nothing else), runs the batched fault loop for DURATION s, follows the robots whose
controller is gone to rest, and returns its rows as plain lists (they cross process boundaries
to the Dask client). A run violates when the true q left the set (min margin < 0 on the oracle).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .bound import upper_95
from .cases import DURATION, FAMILIES, build, fault_specs, scenario_data
from .executor import Chunk, chunk_rng
from .loop import PERIOD, FaultyLoop
from .plant import DEFAULT_CONFIG

REST_LIMIT = 3.0          # s a robot whose controller is gone is followed towards rest
MAX_COUNTEREXAMPLES = 50  # per chunk, kept with their scenario and fault specs


def run_chunk(chunk: Chunk, duration: float = DURATION, families: tuple = FAMILIES,
              brake_torque: float | None = None) -> dict:
    """Chunk `chunk`'s runs, `duration` s of operator each (the seed and index decide everything);
    `families`: the ones the chunks cycle through; `brake_torque` (N·m per wheel): the robots' brakes
    instead of RobotSimConfig's (0: a robot without brakes)."""
    rng = chunk_rng(chunk)
    case = build(chunk.index, chunk.runs, rng, families)
    loop = FaultyLoop(case.problem, case.regions, case.faults, true_theta=case.true_theta, seed=rng,
                      operator_every=10, output_feedback=case.law == "of", brake_torque=brake_torque)
    with np.errstate(all="ignore"):          # rows outside a group are NaN by design (batched/geometry.py)
        loop.run(int(round(duration / PERIOD))).run_to_rest(REST_LIMIT)
    out = loop.result()
    if brake_torque is not None and brake_torque < DEFAULT_CONFIG.brake_torque:
        case = replace(case, inside=np.zeros(chunk.runs, bool))    # weaker brakes than the backup model's: not claimed
    violated = out.min_margin < 0.0
    examples = []
    for i in np.flatnonzero(violated)[:MAX_COUNTEREXAMPLES]:
        d = case.draws
        examples.append({"run": chunk.first_run + int(i), "family": case.family, "law": case.law,
                         "min_margin": float(out.min_margin[i]), "inside_envelope": bool(case.inside[i]),
                         "scenario": scenario_data(case.regions, d["q0"][:, i], d["target"][:, i], d["kp"][i],
                                                   case.law, d["deflection"][i], brake_torque),
                         "faults": fault_specs(case, int(i))})
    draws = {k: np.asarray(v).tolist() for k, v in case.draws.items()
             if k in ("can_delay_ms", "can_loss", "fault_t", "hang_ms", "operator_delay_ms", "operator_loss")}
    if "mismatch" in case.draws:
        draws["mismatch_m1"] = case.draws["mismatch"][0].tolist()
    return {"index": chunk.index, "family": case.family, "law": case.law, "set": case.set_kind,
            "runs": chunk.runs, "min_margin": out.min_margin.tolist(), "violated": violated.tolist(),
            "inside": case.inside.tolist(), "estopped": out.estopped.tolist(), "acted": out.acted.tolist(),
            "approach_speed": np.nan_to_num(out.approach_speed_at_fault, nan=-1.0).tolist(),
            "draws": draws, "counterexamples": examples}


def summarize(results: list[dict], wall_seconds: float) -> dict:
    """The JSON of `sharedctl faults montecarlo` (README of the study: docs/montecarlo.md)."""
    runs = sum(r["runs"] for r in results)
    violated = [v for r in results for v in r["violated"]]
    inside = [v and i for r in results for v, i in zip(r["violated"], r["inside"])]
    margins = [m for r in results for m in r["min_margin"]]
    families = []
    for name in FAMILIES:
        rows = [r for r in results if r["family"] == name]
        if not rows:
            continue
        n = sum(r["runs"] for r in rows)
        k = sum(sum(r["violated"]) for r in rows)
        families.append({"family": name, "runs": n, "violations": k, "upper_95": upper_95(k, n),
                         "inside_envelope": all(all(r["inside"]) for r in rows),
                         "min_margin": min(min(r["min_margin"]) for r in rows),
                         "estops": sum(sum(r["estopped"]) for r in rows)})
    return {"runs": runs, "violations": int(sum(violated)), "violations_inside_envelope": int(sum(inside)),
            "min_margin": float(min(margins)) if margins else None,
            "runs_per_s": runs / wall_seconds if wall_seconds > 0 else None, "wall_seconds": wall_seconds,
            "duration_s": DURATION, "control_rate_hz": 1.0 / PERIOD, "families": families,
            "counterexamples": [c for r in results for c in r["counterexamples"]]}
