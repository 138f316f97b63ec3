"""`sharedctl sim SCENARIO.toml [--controller ce|nce|of] [--json OUT] [--plot OUT.png]`."""
from __future__ import annotations

import sys

from sharedctl.metrics import handover, summarize
from sharedctl.scenario import ScenarioError
from sharedctl.simulator import simulate

from sharedctl.services.scenario_files import load
from sharedctl.services.summary_output import emit


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("sim", help="simulate one scenario in process and print its summary")
    p.add_argument("scenario", help="scenario TOML file, or a packaged name (paper_convex, paper_nonconvex)")
    p.add_argument("--controller", choices=("ce", "nce", "of"), help="machine law (default: the file's, else ce)")
    p.add_argument("--json", metavar="OUT", help="write the summary as JSON to OUT ('-' for stdout)")
    p.add_argument("--plot", metavar="OUT.png", help="draw the run (trajectory in the set and signals) to a PNG")
    p.add_argument("--duration", type=float, help="override the scenario's duration (s)")
    p.set_defaults(handler=run)


def run(args) -> int:
    try:
        scenario = load(args.scenario)
        loop, q0, v0 = scenario.closed_loop(args.controller)
    except ScenarioError as exc:
        print(f"sharedctl sim: {exc}", file=sys.stderr)
        return 2
    duration = args.duration or scenario.duration
    trace = simulate(loop, q0, v0, duration, scenario.dt)
    summary = {"scenario": scenario.name, "controller": loop.controller.name, **summarize(trace, scenario.dt),
               **handover(trace)}
    emit(summary, args.json, _print_table)
    if args.plot:
        from sharedctl.services.studies.figures import run_figure

        run_figure(trace, loop, title=f"{scenario.name} — {loop.controller.name}").savefig(args.plot, dpi=110)
    ok = summary["violations"] == 0 and summary["finite"]
    return 0 if ok else 1


def _print_table(summary: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"{summary['scenario']} ({summary['controller']})", show_header=False)
    for key, value in summary.items():
        if key in ("scenario", "controller"):
            continue
        if isinstance(value, float):
            value = f"{value:.4g}"
        elif isinstance(value, list):
            value = "[" + ", ".join(f"{x:.4g}" for x in value) + "]"
        table.add_row(key, str(value))
    Console().print(table)
