"""`sharedctl faults montecarlo --runs N [--seed S] [--workers W | --scheduler ADDRESS] [--json OUT] [--report DIR]`

The fault Monte-Carlo: N random cases (cases.py) on the batched fault loop (loop.py), in chunks
(executor.py) on a Dask cluster — a local one on this machine's cores by default (127.0.0.1, no
dashboard), or the scheduler at ADDRESS (`dask scheduler` / `dask worker`). The chunks, and so
every figure but the timings, depend on N, the seed and the chunk size only, never on the number
of workers. Writes the JSON (`runs`, `violations`, `violations_inside_envelope`, `min_margin`,
`runs_per_s`, `wall_seconds`, `families` with each family's one-sided 95 % Clopper–Pearson bound
`upper_95`, `counterexamples`) and the report (report.py). Exit 0 unless a run inside the
guarantee's envelope left the set.
"""
from __future__ import annotations

import json
import signal
import sys
import time
from functools import partial
from pathlib import Path

from .cases import DURATION, FAMILIES
from .executor import CHUNK_RUNS



def add_subparser(sub) -> None:
    m = sub.add_parser("montecarlo",
                       help="random fault cases on the batched simulator, on Dask, with a violation bound")
    m.add_argument("--runs", type=int, default=10000, metavar="N", help="number of runs (default 10000)")
    m.add_argument("--seed", type=int, default=0, metavar="S", help="the seed every chunk's draws derive from")
    where = m.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="W",
                       help="local Dask workers on 127.0.0.1 (default: one per core)")
    where.add_argument("--scheduler", metavar="ADDRESS", help="a Dask scheduler, e.g. tcp://127.0.0.1:8786")
    m.add_argument("--chunk-runs", type=int, default=CHUNK_RUNS, metavar="R",
                   help=f"runs per chunk (default {CHUNK_RUNS}; part of what the seed reproduces)")
    m.add_argument("--duration", type=float, default=DURATION, metavar="S",
                   help=f"seconds of operator per run (default {DURATION:g})")
    m.add_argument("--families", metavar="LIST", default=",".join(FAMILIES),
                   help=f"comma-separated fault families the chunks cycle through (default: all: {','.join(FAMILIES)})")
    m.add_argument("--brake-torque", type=float, metavar="NM",
                   help="every robot's fail-safe brake torque per wheel, N·m (default: the robot's own; "
                        "0: robots without brakes, a configuration the guarantee does not cover)")
    m.add_argument("--calibrate", metavar="CAMPAIGN_JSON",
                   help="also run the batched model on the matched cases of a real-process campaign "
                        "(`faults campaign --json`) and compare minimum margins (calibration.py)")
    m.add_argument("--replay", type=int, default=0, metavar="K",
                   help="replay the first K counterexamples outside the envelope once in the real processes "
                        "(`sharedctl demo --scenario … --fault …`, about 10 s each) and report what they did")
    m.add_argument("--json", metavar="OUT", help="write the summary JSON here")
    m.add_argument("--report", metavar="DIR",
                   help="write README.md, the envelope maps and the counterexamples into DIR")
    m.set_defaults(handler=run)


def run(args) -> int:
    from .executor import check_scheduler_address, plan_chunks, run_chunks
    from .work import run_chunk, summarize

    if args.runs < 1 or args.chunk_runs < 1 or not args.duration > 0:
        print("sharedctl faults montecarlo: --runs, --chunk-runs and --duration must be positive", file=sys.stderr)
        return 2
    if args.workers is not None and args.workers < 1:
        print("sharedctl faults montecarlo: --workers must be at least 1", file=sys.stderr)
        return 2
    try:
        scheduler = check_scheduler_address(args.scheduler) if args.scheduler else None
    except ValueError as exc:
        print(f"sharedctl faults montecarlo: {exc}", file=sys.stderr)
        return 2
    families = tuple(f.strip() for f in args.families.split(",") if f.strip())
    unknown = [f for f in families if f not in FAMILIES]
    if unknown or not families:
        print(f"sharedctl faults montecarlo: unknown families {unknown} (known: {', '.join(FAMILIES)})",
              file=sys.stderr)
        return 2
    if args.brake_torque is not None and not args.brake_torque >= 0:
        print("sharedctl faults montecarlo: --brake-torque must be >= 0", file=sys.stderr)
        return 2
    chunks = plan_chunks(args.runs, args.seed, args.chunk_runs)

    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    console = Console(stderr=True)
    tally = {"runs": 0, "violations": 0}
    columns = (TextColumn("[bold]montecarlo[/bold] runs"), BarColumn(), MofNCompleteColumn(),
               TextColumn("viol. {task.fields[violations]}"), TimeElapsedColumn(), TimeRemainingColumn())
    start = time.monotonic()
    previous = signal.signal(signal.SIGTERM, _interrupt)     # SIGTERM as Ctrl-C: the cluster is closed on the way out
    try:
        with Progress(*columns, console=console, transient=False) as progress:
            task = progress.add_task("", total=args.runs, violations=0)

            def on_result(chunk, result, done, total):
                tally["runs"] += result["runs"]
                tally["violations"] += sum(result["violated"])
                progress.update(task, advance=result["runs"], violations=tally["violations"])

            work = partial(run_chunk, duration=args.duration, families=families, brake_torque=args.brake_torque)
            results, info = run_chunks(work, chunks, workers=args.workers,
                                       scheduler=scheduler, on_result=on_result)
    except ImportError as exc:
        print(f"sharedctl faults montecarlo: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"sharedctl faults montecarlo: interrupted after {tally['runs']} of {args.runs} runs; nothing written",
              file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    summary = summarize(results, time.monotonic() - start)
    summary.update(seed=args.seed, chunk_runs=args.chunk_runs, duration_s=args.duration, workers=info.workers,
                   brake_torque=args.brake_torque, families_run=list(families),
                   cluster_startup_seconds=info.startup_seconds, scheduler=scheduler,
                   command=" ".join(["sharedctl faults montecarlo", *sys.argv[3:]]) if len(sys.argv) > 3 else None)
    if args.calibrate:
        from . import calibration
        rows = calibration.matched(json.loads(Path(args.calibrate).read_text())["rows"])
        entries = calibration.table(rows)
        summary["calibration"] = {"campaign": args.calibrate, "classes": calibration.summary(entries),
                                  "table": entries}
    if args.replay > 0:
        import tempfile

        from .replay import replay
        beyond = [c for c in summary["counterexamples"] if not c["inside_envelope"]]
        plan = {"runs": args.runs, "seed": args.seed, "chunk_runs": args.chunk_runs, "families": families,
                "brake_torque": args.brake_torque}
        with tempfile.TemporaryDirectory(prefix="sharedctl-montecarlo-replay-") as workdir:
            summary["replays"] = replay(beyond, Path(workdir), args.duration, args.replay, plan)
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=1) + "\n")
    if args.report:
        from .report import write_report
        write_report(summary, results, Path(args.report))
    console.print(f"sharedctl faults montecarlo: {summary['runs']} runs, {summary['violations']} violations "
                  f"({summary['violations_inside_envelope']} inside the envelope), min margin "
                  f"{summary['min_margin']:.4f} m, {summary['runs_per_s']:.1f} runs/s on {info.workers} workers")
    return 0 if summary["violations_inside_envelope"] == 0 else 1


def _interrupt(signum, frame):
    raise KeyboardInterrupt
