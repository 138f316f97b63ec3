"""`sharedctl paper --out DIR [--duration S] [--controllers ce,nce,of] [--jobs N]`: Section 5 of the paper.

Runs both packaged scenarios (paper_convex, paper_nonconvex) with each machine law, then writes
into DIR:

* fig1_convex_trajectory.png … fig8_nonconvex_of.png — Figures 1–8 of Tang & Sun (2025);
* summary.md — the metrics table, and one line per figure saying what it shows;
* summary.json — the same numbers, one record per run (the `sharedctl sim --json` fields).

Simulations run in a process pool (`simulate` is pure); figures are drawn afterwards.
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

from sharedctl.metrics import summarize
from sharedctl.scenario import ScenarioError
from sharedctl.simulator import simulate

from sharedctl.services.scenario_files import load

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
    """One run (in a worker process): (trace, summary). Pure apart from reading the packaged file."""
    scenario = load(scenario_name)
    loop, q0, v0 = scenario.closed_loop(controller)
    trace = simulate(loop, q0, v0, duration or scenario.duration, scenario.dt)
    return trace, summarize(trace, scenario.dt)


def run(args) -> int:
    from sharedctl.services.studies.figures import Run, paper_figures   # matplotlib only when this command runs

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        scenarios = {name: load(name) for name in SCENARIOS}
    except ScenarioError as exc:
        print(f"sharedctl paper: {exc}", file=sys.stderr)
        return 2
    jobs = [(name, c) for name in SCENARIOS for c in args.controllers]
    started = time.perf_counter()
    results: dict[tuple[str, str], tuple] = {}
    with _Reporter() as report:
        sims = report.task("simulating", len(jobs))
        try:
            with closing(_run_all(jobs, args.duration, max(1, args.jobs))) as finished:   # closing: pool shut down
                for (name, c), (trace, summary) in finished:
                    results[(name, c)] = (trace, summary)
                    report.advance(sims, f"{name} {c}: {summary['steps']} steps, {summary['violations']} "
                                         f"violations, min margin {summary['min_margin']:.4g}")
        except Exception as exc:  # noqa: BLE001 — a failed run must still leave a clear message and a non-zero exit
            print(f"sharedctl paper: simulation failed: {exc!r}", file=sys.stderr)
            return 1
        runs = []
        for name, c in jobs:
            loop, _, _ = scenarios[name].closed_loop(c)
            runs.append(Run(_short(name), c, results[(name, c)][0], loop))
        figures = []
        drawing = report.task("drawing", (len(args.controllers) + 1) * len(SCENARIOS))
        for pf in paper_figures(runs):
            pf.figure.savefig(out / pf.filename, dpi=DPI)
            figures.append({"file": pf.filename, "caption": pf.caption})
            report.advance(drawing, pf.filename)

    records = []
    for (name, c), r in zip(jobs, runs):
        summary = results[(name, c)][1]
        records.append({
            "scenario": scenarios[name].name, "controller": c, **summary,
            "parameter_names": list(r.loop.model.parameter_names),
            "theta_true": [float(x) for x in r.loop.model.theta],
            "dt": scenarios[name].dt,
        })
    ok = all(rec["violations"] == 0 and rec["finite"] for rec in records)
    document = _plain({"ok": ok, "runs": records, "figures": figures})
    (out / "summary.json").write_text(json.dumps(document, indent=2) + "\n")
    (out / "summary.md").write_text(summary_markdown(records, figures, args, ok))
    print(metrics_table(records))
    print(f"\n{'all runs inside Q_a and finite' if ok else 'FAILED: a run left Q_a or diverged'}; "
          f"wrote {len(figures)} figures, summary.md, summary.json to {out} in {time.perf_counter() - started:.1f} s")
    return 0 if ok else 1


def _run_all(jobs, duration, workers):
    """Yield ((scenario, controller), (trace, summary)) as runs finish; the pool is always shut down."""
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


def _number(x, digits=4) -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{digits}g}"


def metrics_table(records: list[dict]) -> str:
    head = ("scenario", "controller", "violations", "min_margin (m)", "tracking_rmse (m)", "final_error (m)",
            "human_authority", "switches", "θ̂ final", "true θ", "finite", "steps")
    rows = ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"]
    for r in records:
        cells = (r["scenario"], r["controller"], str(r["violations"]), _number(r["min_margin"]),
                 _number(r["tracking_rmse"]), _number(r["final_error"]), f"{r['human_authority']:.3f}",
                 str(r["switches"]), "[" + ", ".join(_number(x, 3) for x in r["theta_hat"]) + "]",
                 "[" + ", ".join(_number(x, 3) for x in r["theta_true"]) + "]", "yes" if r["finite"] else "NO",
                 str(r["steps"]))
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def summary_markdown(records: list[dict], figures: list[dict], args, ok: bool) -> str:
    options = "".join([f" --duration {args.duration:g}" if args.duration else "",
                       f" --controllers {','.join(args.controllers)}"
                       if tuple(args.controllers) != CONTROLLERS else ""])
    durations = ", ".join(f"{r['scenario']} {r['duration']:g} s" for r in records[:: max(1, len(args.controllers))])
    names = ", ".join(records[0]["parameter_names"]) if records else ""
    lines = [
        "# Section 5 of Tang & Sun (2025), reproduced",
        "",
        f"Generated by `sharedctl paper --out DIR{options}`: omnidirectional robot, shared control with the",
        f"scripted operator, RK4 at dt = {records[0]['dt'] * 1e3:g} ms; {durations}." if records else "",
        "",
        "## Metrics",
        "",
        metrics_table(records),
        "",
        "- violations: samples with q outside Q_a; min_margin: smallest slack to the nearest face of the best region;",
        "- tracking_rmse / final_error: |q − q_r| against the machine's projected reference q_r;",
        "- human_authority: fraction of samples with u_s = u_h; switches: human ↔ machine authority changes;",
        f"- θ̂ final / true θ: [{names}] at the end of the run (θ̂(0) = 0).",
        "",
        *_law_notes(records),
        f"Result: {'every run stayed inside Q_a and finite.' if ok else '**a run left Q_a or diverged.**'}",
        "",
        "## Figures",
        "",
    ]
    lines += [f"- `{f['file']}` — {f['caption']}." for f in figures]
    return "\n".join(lines) + "\n"


def _law_notes(records: list[dict]) -> list[str]:
    """Say plainly when a run's configured law never ran while the machine acted (`law_share` 0: another law did)."""
    notes = [f"- {r['scenario']} {r['controller']}: the machine acted, but never through this configuration's own "
             f"law (`law_share` 0) — the run is driven by the hazard law (12)." for r in records
             if r.get("law_share") == 0.0]
    return notes + [""] if notes else []


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
