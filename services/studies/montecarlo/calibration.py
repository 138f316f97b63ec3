"""The batched model against the real processes: the cases of a fault campaign (`sharedctl faults
campaign --json`, rows of real `sharedctl demo` runs judged on the simulator's ground truth) that the
batched fault loop can express, run again in one batch per law, their minimum margins side by side.

Matched: a run of a packaged scenario, not behind the secured routers, measured (not an error), whose
faults are only CAN delay and loss (`can.delay_ms`, `can.loss`), a controller kill
(`controller.kill_at`) or hang (`controller.stop_at`). A CAN delay d each way is a feedback age and
a command transit of round(d / 2 ms) periods; a campaign loss drops every frame (encoder estimates
too), the model's only torque frames. The operator is the scenario's, as the console plays it (50
Hz, from the controller's sample).

Two classes, each with its stated agreement |model − ground truth| ≤ tolerance:

* `steady` — no loss of actuation while the robot closes on the wall (CAN delay and loss, hangs shorter
  than the drives' watchdog T_w less a period, kills before the approach or after the stop):
  STEADY_TOLERANCE_M;
* `approach` — a kill, or a hang reaching T_w, while the robot closes on the wall faster than
  APPROACH_SPEED: the braked stop starts from wherever the robot was at the fault's instant, and the
  margin moves by the approach speed (up to ~1.3 m/s) times any offset between the two clocks' t = 0 —
  the real run's is the controller's lease, the model's the operator's first command: APPROACH_TOLERANCE_M.
"""
from __future__ import annotations

import numpy as np

from sharedctl.batched import BatchProblem
from sharedctl.services.scenario_files import load

from .loop import NEVER, PERIOD, FaultyLoop, LoopFaults
from .plant import DEFAULT_CONFIG

MATCHED_FAULTS = ("can.delay_ms", "can.loss", "controller.kill_at", "controller.stop_at")
REST_LIMIT = 3.0
STEADY_TOLERANCE_M = 0.005
APPROACH_TOLERANCE_M = 0.035        # ~25 ms of clock offset at the fastest approach
APPROACH_SPEED = 0.3                # m/s towards the wall at the fault's instant (the model's)
WATCHDOG = DEFAULT_CONFIG.watchdog_timeout       # s, T_w of the drives


def matched(rows: list[dict]) -> list[dict]:
    out = []
    for r in rows:
        keys = [f.partition("=")[0] for f in r["faults"]]
        if (r["outcome"] in ("error", "not exercised") or "[secure]" in r["id"] or r.get("min_margin") is None
                or r["scenario"] != "adversarial_wall" or any(k not in MATCHED_FAULTS for k in keys)):
            continue
        out.append(r)
    return out


def _values(row: dict) -> dict:
    return {k: [float(x) for x in v.split(",")] for k, _, v in (f.partition("=") for f in row["faults"])}


def loses_actuation(row: dict) -> bool:
    """A kill, or a hang that reaches the drives' watchdog (within a period): the drives disarm."""
    values = _values(row)
    return "controller.kill_at" in values or values.get("controller.stop_at", [0, 0])[1] >= WATCHDOG - PERIOD


def model_margins(rows: list[dict], duration: float | None = None) -> tuple[list[float], list[float]]:
    """The batched loop's minimum margin of each row (same order), one batch per (scenario, law), and the
    speed at which it closed on the wall at the fault's instant (NaN without a kill or hang)."""
    out = [np.nan] * len(rows)
    speed = [np.nan] * len(rows)
    groups: dict = {}
    for i, r in enumerate(rows):
        groups.setdefault((r["scenario"], r["law"]), []).append(i)
    for (scenario, law), index in groups.items():
        loop, q0, v0 = load(scenario).closed_loop(law)
        N = len(index)
        faults = LoopFaults.none(N)
        values = [_values(rows[i]) for i in index]
        delay = np.array([v.get("can.delay_ms", [0.0])[0] for v in values])
        periods = np.rint(delay / (PERIOD * 1000.0)).astype(np.int64)
        kill = [round(v["controller.kill_at"][0] / PERIOD) if "controller.kill_at" in v else NEVER for v in values]
        hang = [v.get("controller.stop_at") for v in values]
        faults = faults.replace(feedback=periods, transit=periods,
                                torque_loss=[v.get("can.loss", [0.0])[0] for v in values], kill_at=kill,
                                hang_at=[round(h[0] / PERIOD) if h else NEVER for h in hang],
                                hang_periods=[round(h[1] / PERIOD) if h else 0 for h in hang])
        problem = BatchProblem.replicate(loop, np.tile(q0, (N, 1)), np.tile(v0, (N, 1)))
        regions = [(r.K, r.T) for r in loop.feasible.regions]
        run = FaultyLoop(problem, regions, faults, seed=0, operator_every=10, output_feedback=law == "of")
        length = duration or max(rows[i]["duration"] for i in index)
        with np.errstate(all="ignore"):
            result = run.run(int(round(length / PERIOD))).run_to_rest(REST_LIMIT).result()
        for j, i in enumerate(index):
            out[i] = float(result.min_margin[j])
            speed[i] = float(result.approach_speed_at_fault[j])
    return out, speed


def table(rows: list[dict]) -> list[dict]:
    """Per matched row: id, law, faults, class, ground truth and model minimum margins (m), their difference
    and whether it is within the class's tolerance."""
    model, speed = model_margins(rows)
    out = []
    for r, m, v in zip(rows, model, speed):
        kind = "approach" if loses_actuation(r) and v > APPROACH_SPEED else "steady"
        tolerance = APPROACH_TOLERANCE_M if kind == "approach" else STEADY_TOLERANCE_M
        difference = m - float(r["min_margin"])
        out.append({"id": r["id"], "law": r["law"], "faults": r["faults"], "class": kind,
                    "ground_truth": float(r["min_margin"]), "model": m, "difference": difference,
                    "approach_speed": v, "tolerance": tolerance, "agrees": bool(abs(difference) <= tolerance)})
    return out


def summary(entries: list[dict]) -> dict:
    """Per class: cases, how many agree, the largest |difference|, and the cases that do not agree."""
    out = {}
    for kind in ("steady", "approach"):
        rows = [e for e in entries if e["class"] == kind]
        if rows:
            out[kind] = {"cases": len(rows), "agree": sum(e["agrees"] for e in rows),
                         "tolerance_m": rows[0]["tolerance"],
                         "max_abs_difference_m": max(abs(e["difference"]) for e in rows),
                         "disagree": [e["id"] for e in rows if not e["agrees"]]}
    return out
