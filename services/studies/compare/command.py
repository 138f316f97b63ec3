"""`sharedctl compare [--quick] [--json OUT] [--report DIR]`: every strategy on every scenario, two link conditions.

Strategies (sharedctl/baselines/): `human` (the operator alone), `mux` (twist_mux-style
priority/timeout arbitration with a hold at the border), `cbf` (a relative-degree-2 CBF QP
safety filter), `shared` (the paper's law with the backup-safe sets of sharedctl/backup.py) and
`shared-nobackup` (the same law with `[backup] enabled = false`, the paper's loop). Each runs in
the same sampled loop (500 Hz, plant RK4 at 2 kHz) behind the same in-process operator link, once
ideal and once with 100 ms each way and 20 % command loss (seeded). The JSON's `results` hold one
row per run with `strategy`, `scenario` (the scenario and the condition), `base_scenario`,
`condition` and the metrics of sharedctl/baselines/comparison_metrics.py (`goal_tolerance` is
time_to_goal's); `backup_price` pairs `shared` with `shared-nobackup` per scenario and condition
(price.py); `model_sensitivity` repeats `mux` and `cbf` on the adversarial scenarios with wrong
nominal parameters (θ̂ = 0.5θ and 2θ). Exit 1 if either shared variant violated the set anywhere
(the one guarantee this command checks), 2 on bad arguments.
"""
from __future__ import annotations

import json
import sys
from dataclasses import asdict, dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from sharedctl.baselines.comparison import CONTROL_PERIOD, STRATEGIES, ComparisonTrace, build_strategy, run
from sharedctl.baselines.comparison_metrics import GOAL_TOLERANCE, summarize
from sharedctl.baselines.operator_link import IDEAL, IMPAIRED, LinkConditions

from .price import backup_price
from .scenarios import Entry, scenario_set

CONDITIONS = (IDEAL, IMPAIRED)


@dataclass
class Outcome:
    """One run: its row for the JSON and what the report draws."""

    row: dict
    entry: Entry
    condition: LinkConditions
    trace: ComparisonTrace
    loop: object


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("compare", help="compare human, mux, CBF and shared control (with and without the "
                                              "backup-safe sets) on the scenario set")
    p.add_argument("--quick", action="store_true", help="shorter paper runs (minutes, not the committed report)")
    p.add_argument("--json", metavar="OUT", help="write the results as JSON to OUT ('-' for stdout)")
    p.add_argument("--report", metavar="DIR", help="write report.md and its figures to DIR")
    p.add_argument("--strategies", default=",".join(STRATEGIES), help="comma-separated subset (default: all)")
    p.add_argument("--duration", type=float, help="override every run's length (s)")
    p.set_defaults(handler=handle)


def compare(entries: list[Entry], strategies=STRATEGIES, conditions=CONDITIONS, progress=None) -> list[Outcome]:
    """Run every strategy on every scenario under every condition."""
    outcomes = []
    for entry in entries:
        for condition in conditions:
            for name in strategies:
                loop, q0, v0 = entry.scenario.closed_loop()
                trace = run(build_strategy(name, loop), loop, q0, v0, entry.duration, condition)
                label = entry.scenario.name if condition is IDEAL else f"{entry.scenario.name}/{condition.name}"
                row = {"strategy": name, "scenario": label, "base_scenario": entry.scenario.name,
                       "condition": condition.name, **summarize(trace, loop.feasible, CONTROL_PERIOD),
                       "commands_sent": trace.commands_sent, "commands_lost": trace.commands_lost}
                outcomes.append(Outcome(row, entry, condition, trace, loop))
                if progress:
                    progress(row)
    return outcomes


THETA_SCALES = (0.5, 2.0)   # the nominal parameters given to mux and cbf in the model-error runs: θ̂ = s·θ


def model_sensitivity(entries: list[Entry], strategies=("mux", "cbf"), scales=THETA_SCALES,
                      progress=None) -> list[dict]:
    """The model-based baselines with wrong nominal parameters, on the adversarial scenarios (ideal link).

    `mux` and `cbf` use M̂, Ĉ, ĝ; the shared law needs none (its θ̂ starts at 0 and adapts), so
    it has no counterpart here.
    """
    rows = []
    for entry in entries:
        if not entry.scenario.name.startswith("adversarial"):
            continue
        for scale in scales:
            for name in strategies:
                loop, q0, v0 = entry.scenario.closed_loop()
                trace = run(build_strategy(name, loop, theta=scale * loop.model.theta), loop, q0, v0, entry.duration)
                row = {"strategy": name, "scenario": f"{entry.scenario.name}/theta*{scale:g}",
                       "base_scenario": entry.scenario.name, "theta_scale": scale,
                       **summarize(trace, loop.feasible, CONTROL_PERIOD)}
                rows.append(row)
                if progress:
                    progress(row)
    return rows


def document(outcomes: list[Outcome], quick: bool, sensitivity: list[dict] | None = None) -> dict:
    """The JSON document."""
    entries = {o.entry.scenario.name: o.entry for o in outcomes}
    try:
        ver = version("sharedctl")
    except PackageNotFoundError:
        ver = "unknown"
    return {
        "version": ver,
        "quick": quick,
        "control_period": CONTROL_PERIOD,
        "goal_tolerance": GOAL_TOLERANCE,
        "strategies": sorted({o.row["strategy"] for o in outcomes}, key=STRATEGIES.index),
        "conditions": {c.name: asdict(c) for c in CONDITIONS},
        "scenarios": [{"name": n, "duration": e.duration, "source": e.source} for n, e in entries.items()],
        "results": [o.row for o in outcomes],
        "backup_price": backup_price(outcomes),
        "model_sensitivity": sensitivity or [],
    }


def handle(args) -> int:
    strategies = tuple(s for s in args.strategies.split(",") if s)
    unknown = [s for s in strategies if s not in STRATEGIES]
    if unknown or not strategies or (args.duration is not None and args.duration <= 0):
        print(f"sharedctl compare: strategies must be among {', '.join(STRATEGIES)}; --duration > 0", file=sys.stderr)
        return 2
    quiet = args.json == "-"
    progress = None if quiet else _progress_line
    entries = scenario_set(args.quick, args.duration)
    outcomes = compare(entries, strategies, CONDITIONS, progress)
    sensitivity = model_sensitivity(entries, tuple(s for s in ("mux", "cbf") if s in strategies), progress=progress)
    doc = document(outcomes, args.quick, sensitivity)
    text = json.dumps(doc, indent=2)
    if args.json == "-":
        print(text)
    elif args.json:
        Path(args.json).write_text(text + "\n")
    if args.report:
        from .report import write_report

        path = write_report(outcomes, doc, Path(args.report))
        if not quiet:
            print(f"report: {path}")
    shared_bad = [f"{o.row['scenario']} ({o.row['strategy']})" for o in outcomes
                  if o.row["strategy"].startswith("shared") and (o.row["violations"] or not o.row["finite"])]
    if shared_bad:
        print(f"sharedctl compare: the shared law violated the set in {', '.join(shared_bad)}", file=sys.stderr)
        return 1
    return 0


def _progress_line(row: dict) -> None:
    goal = "—" if row.get("time_to_goal") is None else f"{row['time_to_goal']:.2f} s"
    print(f"{row['scenario']:34s} {row['strategy']:15s} violations {row['violations']:5d}  "
          f"min margin {row['min_margin']:+.3f} m  tracking {row['tracking_error']:.3f}  goal {goal:>7s}  "
          f"authority {row['human_authority']:.2f}  interventions {row['interventions']:3d}  "
          f"effort {row['control_effort']:.3g} N²s  jerk {row['jerk_rms']:.3g}", flush=True)
