"""`sharedctl faults campaign [--quick] [--json OUT] [--report DIR]` — the fault campaign.

Runs the matrix (matrix.py) one `sharedctl demo --fault …` at a time (this host has two cores:
runs never overlap), judges each on the simulator's ground truth and against the forecasts of
what its faults force (judge.py, docs/safety.md), shows a progress bar, and writes the JSON
(`runs`, `violations`, `min_margin`, `rows`, …; rewritten after every run, so an interrupted
campaign keeps what it measured) and the report (markdown table and plots). SIGINT/SIGTERM
stop it after the current run. Exit 0 only if every run was measured and no violation falls
outside the documented limits.
"""
from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

from sharedctl.services.lifecycle import StopFlag
from . import judge as jd
from . import matrix as cp


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("faults", help="fault studies: the campaign of real processes, the batched Monte-Carlo")
    sub = p.add_subparsers(dest="faults_command", required=True, metavar="ACTION")
    c = sub.add_parser("campaign", help="run scenarios × faults as demo runs and judge them on the ground truth")
    c.add_argument("--quick", action="store_true", help="every fault family once (~20 runs) instead of the full matrix")
    c.add_argument("--json", metavar="OUT", help="write the campaign's JSON here (rewritten after every run)")
    c.add_argument("--report", metavar="DIR", help="write README.md and the plots into DIR")
    c.add_argument("--only", metavar="TEXT", action="append", default=[],
                   help="run only the cases whose id contains TEXT (repeatable: any of them)")
    c.add_argument("--resume", action="store_true",
                   help="keep the measured rows of an existing --json OUT, run the rest (and the runs not exercised)")
    c.add_argument("--retries", type=int, default=1, metavar="N",
                   help="run a case again, at most N times, when an estop before its start left it not exercised "
                        "(default 1)")
    c.add_argument("--budget", type=float, metavar="S", help="start no new run after S seconds")
    c.add_argument("--keep-logs", metavar="DIR", help="keep every run's JSON and process logs in DIR")
    c.add_argument("--list", action="store_true", help="print the cases and exit")
    c.add_argument("--rejudge", metavar="LOGDIR",
                   help="run nothing: judge the rows of --json OUT again from the summaries kept in LOGDIR")
    p.set_defaults(handler=run)
    from ..montecarlo.command import add_subparser
    add_subparser(sub)


class Forecasts:
    """The judge's forecasts (judge.py) on the robot's true plant, cached per scenario and law."""

    def __init__(self) -> None:
        self.plants: dict = {}
        self.delays: dict = {}

    def delay(self, scenario: str, duration: float, controller: str | None, loop_delay: float, hang=None) -> dict:
        """Min margin of the in-process sampled loop with the torque loop delayed by loop_delay (and by two
        periods more: the distributed loop's rounding), or with the controller hung over `hang` = (START,
        DURATION) at its actual instant; `best_min_margin` is the better of the runs."""
        from sharedctl.services.scenario_files import load
        from . import stopping

        key = (scenario, controller, round(loop_delay, 4), duration, hang)
        if key not in self.delays:
            lags = (loop_delay, loop_delay + 2 * stopping.CONTROL_PERIOD) if hang is None else (loop_delay,)
            margins = [stopping.delayed_loop_margin(load(scenario), duration, lag, controller, hang=hang)[0]
                       for lag in lags]
            self.delays[key] = {"loop_delay": loop_delay, "hang": hang, "min_margin": round(margins[0], 4),
                                "best_min_margin": round(max(margins), 4)}
        return self.delays[key]

    def coast(self, scenario: str, controller: str | None, state: dict, holds) -> dict | None:
        """A loss of actuation forecast from the run's ground truth at the instant it happened (`state`: a
        `fault_states` entry of the demo's JSON), the best over the held torques and `holds`."""
        from . import stopping

        key = (scenario, controller)
        if key not in self.plants:
            from sharedctl.services.scenario_files import load
            self.plants[key] = stopping.true_plant(load(scenario), controller)
        plant, feasible = self.plants[key]
        out = stopping.forecast_at(plant, feasible, state["truth"], state.get("torques") or [], state["t"],
                                   tuple(holds))
        return None if out is None else {k: round(float(v), 4) for k, v in vars(out).items()}


def run(args) -> int:
    if args.faults_command != "campaign":
        return 2
    cases = cp.plan(args.quick)
    if args.only:
        cases = [c for c in cases if any(text in c.id for text in args.only)]
    if args.list:
        for i, c in enumerate(cases):
            print(f"{i:4d}  {c.id}")
        return 0
    try:
        from sharedctl.services.faults.spec import parse
    except ImportError:
        unsupported = {}
    else:
        unsupported = cp.validate(cases, parse)
    for cid, reason in unsupported.items():
        print(f"sharedctl faults: skipping {cid}: {reason}", file=sys.stderr)
    cases = [c for c in cases if c.id not in unsupported]
    json_out = Path(args.json) if args.json else None
    if args.rejudge:
        return _rejudge(args, json_out)
    kept = []
    if args.resume and json_out is not None and json_out.exists():
        kept = [r for r in json.loads(json_out.read_text())["rows"] if r["outcome"] not in ("error", "not exercised")]
        done = {r["id"] for r in kept}
        cases = [c for c in cases if c.id not in done]
    meta = {"command": "sharedctl faults campaign" + (" --quick" if args.quick else ""),
            "started": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "host": f"{os.cpu_count()} CPUs", "load_before": _load(), "skipped": unsupported}
    stop = StopFlag().install()
    workdir = Path(args.keep_logs) if args.keep_logs else Path(tempfile.mkdtemp(prefix="sharedctl-campaign-"))
    workdir.mkdir(parents=True, exist_ok=True)
    runner = cp.subprocess_runner(workdir, first_index=_next_index(workdir))
    start = time.monotonic()
    rows = list(kept)

    def should_stop():
        return stop.stopped or (args.budget is not None and time.monotonic() - start > args.budget)

    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    console = Console(stderr=True)
    columns = (TextColumn("[bold]faults[/bold] {task.description}"), BarColumn(), MofNCompleteColumn(),
               TextColumn("viol. {task.fields[violating]} · estop {task.fields[estops]} · min {task.fields[margin]}"),
               TimeElapsedColumn(), TimeRemainingColumn())
    with Progress(*columns, console=console, transient=False) as progress:
        task = progress.add_task(cases[0].id if cases else "", total=len(cases), violating=0, estops=0, margin="–")

        def on_row(row, done, total):
            rows.append(row)
            agg = jd.aggregate(rows, meta)
            if json_out is not None:
                jd.write_json(json_out, agg)
            if row["violations"] or row["outcome"] == "error":
                progress.console.print(f"  {row['outcome']}: {row['id']} (min margin {row['min_margin']}; "
                                       f"{row['explained'] or row['error'] or row['failure'] or 'unexplained'})")
            nxt = cases[done].id if done < total else "done"
            margin = "–" if agg["min_margin"] is None else f"{agg['min_margin']:.3f} m"
            progress.update(task, advance=1, description=nxt, violating=agg["violating_runs"],
                            estops=agg["estop_runs"], margin=margin)

        cp.run_campaign(cases, runner, Forecasts(), on_row, should_stop, max(args.retries, 0))
    meta["load_after"] = _load()
    result = jd.aggregate(rows, meta)
    result["interrupted"] = len(rows) < len(kept) + len(cases)
    if json_out is not None:
        jd.write_json(json_out, result)
    if args.report:
        from .report import write_report
        write_report(result, Path(args.report), "Fault campaign" + (" (quick)" if args.quick else ""))
    if not args.keep_logs:
        import shutil
        shutil.rmtree(workdir, ignore_errors=True)
    console.print(f"sharedctl faults: {result['runs']} runs, {result['violating_runs']} with violations "
                  f"({len(result['unexpected_violations'])} unexpected), {len(result['errors'])} without data, "
                  f"min margin {result['min_margin']}")
    return 0 if result["ok"] and not result["errors"] and result["runs"] > 0 else 1


def _next_index(workdir: Path) -> int:
    """The first free runNNNN index in `workdir` (a resumed campaign keeps the earlier summaries)."""
    used = [int(p.stem[3:7]) for p in workdir.glob("run[0-9][0-9][0-9][0-9].json")]
    return max(used) + 1 if used else 0


def _rejudge(args, json_out: Path | None) -> int:
    if json_out is None or not json_out.exists():
        print("sharedctl faults: --rejudge needs --json OUT of an earlier campaign", file=sys.stderr)
        return 2
    old = json.loads(json_out.read_text())
    meta = {k: v for k, v in old.items() if k in ("command", "started", "host", "load_before", "load_after",
                                                   "skipped", "interrupted", "note")}
    result = jd.aggregate(cp.rejudge(old["rows"], Path(args.rejudge), Forecasts()), meta)
    jd.write_json(json_out, result)
    if args.report:
        from .report import write_report
        write_report(result, Path(args.report),
                     "Fault campaign" + (" (quick)" if "--quick" in meta.get("command", "") else ""))
    print(f"sharedctl faults: {result['runs']} runs judged again, {result['violating_runs']} with violations "
          f"({len(result['unexpected_violations'])} unexpected)")
    return 0 if result["ok"] else 1


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "unknown"
