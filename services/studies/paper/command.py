"""`sharedctl paper --out DIR [--duration S] [--controllers ce,nce,of] [--jobs N]`: Section 5 of the paper.

Runs both packaged scenarios (paper_convex, paper_nonconvex) with each machine law, then writes
into DIR:

* fig1_convex_trajectory.png … fig8_nonconvex_of.png — Figures 1–8 of Tang & Sun (2025);
* summary.json — one record per scenario and law: the `sharedctl sim --json` fields, the applied
  force's and the wheel torques' sizes, the time of full machine authority (table.py), each
  figure's caption, and what each configuration runs (laws.py);
* summary.md — rendered from summary.json: the table, Remark 3's θ errors, the captions.

Simulations run in a process pool (`simulate` is pure); figures are drawn afterwards. Every
caption and record names its law from laws.describe, read off the controller that ran.
Exit code 0 only if every run stayed inside Q_a (0 violations) and finite; 1 otherwise.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from contextlib import closing
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from sharedctl.scenario import ScenarioError
from sharedctl.simulator import simulate

from sharedctl.services.scenario_files import load
from sharedctl.services.studies.paper.laws import ConfigurationMismatch, describe
from sharedctl.services.studies.paper.table import metrics_table, run_record, summary_markdown

SCENARIOS = ("paper_convex", "paper_nonconvex")
CONTROLLERS = ("ce", "nce", "of")
DPI = 100


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("paper", help="reproduce the paper's Section 5: Figures 1–8 and a metrics summary")
    p.add_argument("--out", required=True, metavar="DIR", help="directory for the PNGs, summary.md and summary.json")
    p.add_argument("--duration", type=_positive, metavar="S", help="override every scenario's duration (s)")
    p.add_argument("--controllers", type=_controller_list, default=CONTROLLERS, metavar="LIST",
                   help="comma-separated machine laws to run (default: ce,nce,of)")
    p.add_argument("--jobs", type=int, default=2, metavar="N",
                   help="simulations in parallel (default 2; 1 = in process)")
    p.set_defaults(handler=run)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (value > 0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"must be a positive number of seconds, got {text!r}")
    return value


def _controller_list(text: str) -> tuple[str, ...]:
    names = tuple(dict.fromkeys(x.strip() for x in text.split(",") if x.strip()))
    bad = [x for x in names if x not in CONTROLLERS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"expected a comma-separated subset of {','.join(CONTROLLERS)}, got {text!r}")
    return tuple(c for c in CONTROLLERS if c in names)   # paper order


def simulate_one(scenario_name: str, controller: str, duration: float | None):
    """One run (in a worker process): (trace, its table record). Pure apart from reading the packaged file."""
    scenario = load(scenario_name)
    loop, q0, v0 = scenario.closed_loop(controller)
    trace = simulate(loop, q0, v0, duration or scenario.duration, scenario.dt)
    return trace, run_record(scenario, controller, describe(controller, loop.controller), trace, loop)


def run(args) -> int:
    from sharedctl.services.studies.figures import Run, paper_figures   # matplotlib only when this command runs

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        scenarios = {name: load(name) for name in SCENARIOS}
        loops = {(name, c): scenarios[name].closed_loop(c)[0] for name in SCENARIOS for c in args.controllers}
        laws = {key: describe(key[1], loop.controller) for key, loop in loops.items()}
    except (ScenarioError, ConfigurationMismatch) as exc:
        print(f"sharedctl paper: {exc}", file=sys.stderr)
        return 2
    jobs = list(loops)
    started = time.perf_counter()
    results: dict[tuple[str, str], tuple] = {}
    with _Reporter() as report:
        sims = report.task("simulating", len(jobs))
        try:
            with closing(_run_all(jobs, args.duration, max(1, args.jobs))) as finished:   # closing: pool shut down
                for (name, c), (trace, record) in finished:
                    results[(name, c)] = (trace, record)
                    report.advance(sims, f"{name} {c}: {record['steps']} steps, {record['violations']} "
                                         f"violations, min margin {record['min_margin']:.4g}")
        except Exception as exc:  # noqa: BLE001 — a failed run must still leave a clear message and a non-zero exit
            print(f"sharedctl paper: simulation failed: {exc!r}", file=sys.stderr)
            return 1
        runs = [Run(_short(name), c, results[(name, c)][0], loops[(name, c)], laws[(name, c)]) for name, c in jobs]
        figures = []
        drawing = report.task("drawing", (len(args.controllers) + 1) * len(SCENARIOS))
        for pf in paper_figures(runs):
            pf.figure.savefig(out / pf.filename, dpi=DPI)
            figures.append({"file": pf.filename, "caption": pf.caption})
            report.advance(drawing, pf.filename)

    document = paper_document([results[key][1] for key in jobs], figures)
    (out / "summary.json").write_text(json.dumps(document, indent=2) + "\n")
    (out / "summary.md").write_text(summary_markdown(document, command_line(args)))
    print(metrics_table(document["runs"]))
    print(f"\n{'all runs inside Q_a and finite' if document['ok'] else 'FAILED: a run left Q_a or diverged'}; "
          f"wrote {len(figures)} figures, summary.md, summary.json to {out} in {time.perf_counter() - started:.1f} s")
    return 0 if document["ok"] else 1


def paper_document(records: list[dict], figures: list[dict]) -> dict:
    """summary.json: ok, what each configuration runs, one record per scenario and law, the figures' captions."""
    ok = all(r["violations"] == 0 and r["finite"] for r in records)
    configurations = {r["controller"]: r["law"] for r in records}
    return _plain({"ok": ok, "configurations": configurations, "runs": records, "figures": figures})


def command_line(args) -> str:
    """The command that reproduces the output (the output directory as DIR)."""
    options = "".join([f" --duration {args.duration:g}" if args.duration else "",
                       f" --controllers {','.join(args.controllers)}"
                       if tuple(args.controllers) != CONTROLLERS else ""])
    return f"sharedctl paper --out DIR{options}"


def _run_all(jobs, duration, workers):
    """Yield ((scenario, controller), (trace, record)) as runs finish; the pool is always shut down."""
    if workers == 1:
        for name, c in jobs:
            yield (name, c), simulate_one(name, c, duration)
        return
    pool = ProcessPoolExecutor(max_workers=workers)
    try:
        futures = {pool.submit(simulate_one, name, c, duration): (name, c) for name, c in jobs}
        for future in as_completed(futures):
            yield futures[future], future.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _short(scenario_name: str) -> str:
    return scenario_name.removeprefix("paper_")


def _plain(value):
    """JSON without NaN/Infinity (null instead), so any parser reads it."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


class _Reporter:
    """A rich progress bar on a terminal; plain, one-line-per-event output otherwise (CI, pipes)."""

    def __enter__(self):
        self.progress = None
        if sys.stdout.isatty():
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

            self.progress = Progress(TextColumn("{task.description:<11}"), BarColumn(bar_width=30),
                                     MofNCompleteColumn(), TimeElapsedColumn(), TextColumn("{task.fields[note]}"))
            self.progress.__enter__()
        self.totals: dict[int, tuple[str, int, int]] = {}
        return self

    def task(self, description: str, total: int) -> int:
        if self.progress:
            return self.progress.add_task(description, total=total, note="")
        key = len(self.totals)
        self.totals[key] = (description, total, 0)
        return key

    def advance(self, task: int, note: str) -> None:
        if self.progress:
            self.progress.update(task, advance=1, note=note)
            return
        description, total, done = self.totals[task]
        self.totals[task] = (description, total, done + 1)
        print(f"[{description} {done + 1}/{total}] {note}", flush=True)

    def __exit__(self, *exc):
        if self.progress:
            self.progress.__exit__(*exc)
        return False
