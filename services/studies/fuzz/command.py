"""``sharedctl fuzz``: run the protocol fuzz campaign on demand and print a summary table."""
from __future__ import annotations

import argparse
import time

from rich.console import Console
from rich.table import Table

from sharedctl.protocol.fuzz import DECODERS, FuzzReport, run_campaign


def _positive(text: str) -> int:
    value = int(text)
    if value <= 0:
        raise argparse.ArgumentTypeError("must be a positive integer")
    return value


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``fuzz`` sub-command."""
    parser = subparsers.add_parser(
        "fuzz",
        help="fuzz the wire decoders (CAN frames, Zenoh payloads, key expressions)",
        description="Feed random and mutated inputs to each protocol decoder. Every input must "
                    "decode to a valid value or raise the typed ProtocolError; anything else is an escape.",
    )
    parser.add_argument("--count", type=_positive, default=100_000, metavar="N",
                        help="inputs per decoder (default: 100000)")
    parser.add_argument("--seed", type=int, default=0, metavar="S", help="campaign seed (default: 0)")
    parser.add_argument("--decoder", choices=[*DECODERS, "all"], default="all",
                        help="decoder to fuzz (default: all)")
    parser.set_defaults(handler=run)
    return parser


def summary_table(rows: list[tuple[FuzzReport, float]]) -> Table:
    """Rich table of campaign results, one row per decoder."""
    table = Table(title="sharedctl protocol fuzz")
    for column in ("decoder", "inputs", "typed errors", "accepted", "escapes", "seconds", "inputs/s"):
        table.add_column(column, justify="left" if column == "decoder" else "right")
    for report, seconds in rows:
        style = "green" if report.ok else "bold red"
        rate = report.inputs / seconds if seconds > 0 else float("inf")
        table.add_row(report.decoder, f"{report.inputs:,}", f"{report.typed_errors:,}", f"{report.accepted:,}",
                      f"[{style}]{report.escapes}[/{style}]", f"{seconds:.2f}", f"{rate:,.0f}")
    return table


def run(args: argparse.Namespace, console: Console | None = None) -> int:
    """Run the campaign; exit code 0 when no decoder let anything but a typed error escape."""
    console = console or Console()
    decoders = DECODERS if args.decoder == "all" else (args.decoder,)
    rows = []
    for decoder in decoders:
        start = time.perf_counter()
        report = run_campaign(decoder, args.count, args.seed)
        rows.append((report, time.perf_counter() - start))
    console.print(summary_table(rows))
    failed = [report for report, _ in rows if not report.ok]
    for report in failed:
        for example in report.examples:
            console.print(f"[red]escape[/red] {example}", markup=True, highlight=False)
    return 1 if failed else 0
