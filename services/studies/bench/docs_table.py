"""The "Latest figures" table of docs/performance.md, from two recorded bench runs.

    python -m sharedctl.services.studies.bench.docs_table docs/performance/bench.json docs/performance/bench-quick.json

prints the table (Markdown) with one row per figure: its JSON key, its target and the value in the
full and in the `--quick` run; in brackets, the bare loop's figure of the same run. The page's
table is this command's output, pasted whole: regenerate it, never edit a figure by hand.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

# (label, target, keys, decimals): the keys' values are joined with " / "; a key after "|" goes in
# brackets (the bare loop's figure); a key after "@" in parentheses (what the figure was taken over);
# decimals: one for every key, or one per key in order
ROWS = (
    ("`control_step_us.ce.median` (machine law engaged, µs)", "≤ 50", ["control_step_us.ce.median"], 1),
    ("`control_step_us.ce.thread_cpu_median`", "", ["control_step_us.ce.thread_cpu_median"], 1),
    ("`control_step_us.ce.without_backup.median` (`[backup] enabled = false`)", "",
     ["control_step_us.ce.without_backup.median"], 1),
    ("`control_step_us.{nce,of}.median`", "", ["control_step_us.nce.median", "control_step_us.of.median"], 1),
    ("`control_step_us.ce.operator_only.median`", "", ["control_step_us.ce.operator_only.median"], 1),
    ("`loop.deadline_misses` [`machine_floor.deadline_misses`]", "0",
     ["loop.deadline_misses", "|machine_floor.deadline_misses"], 0),
    ("`loop.jitter_p99_us` [`machine_floor.bus.jitter_p99_us`]", "≤ 300",
     ["loop.jitter_p99_us", "|machine_floor.bus.jitter_p99_us"], 0),
    ("`latency.sensor_to_torque_us.p50` / `.p99` (on the bus)", "p99 ≤ 1,000",
     ["latency.sensor_to_torque_us.p50", "latency.sensor_to_torque_us.p99"], 0),
    ("`loop.daemon.torque_out_p50_us` / `_p99_us` [`machine_floor.pre_send_wall_us`]", "",
     ["loop.daemon.torque_out_p50_us", "loop.daemon.torque_out_p99_us",
      "|machine_floor.pre_send_wall_us.p50", "|machine_floor.pre_send_wall_us.p99"], 0),
    ("`loop.daemon.loop_cpu_p50_us` / `_p99_us` [`machine_floor.work_thread_cpu_us`]", "",
     ["loop.daemon.loop_cpu_p50_us", "loop.daemon.loop_cpu_p99_us",
      "|machine_floor.work_thread_cpu_us.p50", "|machine_floor.work_thread_cpu_us.p99"], 0),
    ("`loop.daemon.lateness_p99_us` [`machine_floor.lateness_us.p99`]", "",
     ["loop.daemon.lateness_p99_us", "|machine_floor.lateness_us.p99"], (0, 1)),
    ("`latency.operator_to_torque_us.p50`", "", ["latency.operator_to_torque_us.p50"], 0),
    ("`latency.operator_to_torque_by_qos_us`: `default.p50` / `.p99`, `streams.p50` / `.p99`", "",
     ["latency.operator_to_torque_by_qos_us.default.p50", "latency.operator_to_torque_by_qos_us.default.p99",
      "latency.operator_to_torque_by_qos_us.streams.p50", "latency.operator_to_torque_by_qos_us.streams.p99"], 0),
    ("`latency.zenoh_floor_us.p50` / `latency.can_floor_us.p50`", "",
     ["latency.zenoh_floor_us.p50", "latency.can_floor_us.p50"], (0, 1)),
    ("`bus_load.fraction_1mbit` (worst-case stuffing)", "≤ 0.5", ["bus_load.fraction_1mbit"], 3),
    ("`cpu.fraction_of_one_core` (robot + controller, 500 Hz)", "", ["cpu.fraction_of_one_core"], 3),
    ("`loop_1khz.rate_hz` / `loop_1khz.bus_load.fraction_1mbit`", "",
     ["loop_1khz.rate_hz", "loop_1khz.bus_load.fraction_1mbit"], (0, 3)),
    ("`loop_free_running.sensor_to_torque_us.p50`", "", ["loop_free_running.sensor_to_torque_us.p50"], 0),
    ("`batched_sim.steps_per_s` (`batched_sim.robots`)", "≥ 1,000,000",
     ["batched_sim.steps_per_s", "@batched_sim.robots"], 0),
    ("`batched_sim.without_backup.steps_per_s` (no governor)", "", ["batched_sim.without_backup.steps_per_s"], 0),
    ("`batched_sim.speedup_vs_scalar`", "≥ 50", ["batched_sim.speedup_vs_scalar"], 0),
    ("`cpu.steal_s` [`machine_floor.steal_s`]", "", ["cpu.steal_s", "|machine_floor.steal_s"], 2),
)


def lookup(run: dict, key: str):
    value = run
    for part in key.split("."):
        value = value.get(part) if isinstance(value, dict) else None
    return value


def number(value, decimals: int) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    if isinstance(value, int) or decimals == 0:
        return f"{round(value):,}"
    return f"{value:,.{decimals}f}"


def cell(run: dict, keys: list[str], decimals) -> str:
    """The plain keys joined by " / ", then the bare loop's in brackets and the extent in parentheses."""
    groups = {"": [], "|": [], "@": []}
    for i, key in enumerate(keys):
        mark = key[0] if key[0] in "|@" else ""
        places = decimals[i % len(decimals)] if isinstance(decimals, tuple) else decimals
        value = lookup(run, key.lstrip("|@"))
        groups[mark].append(number(value, 0 if mark == "@" else places))
    text = " / ".join(groups[""])
    if groups["|"]:
        text += f" [{' / '.join(groups['|'])}]"
    if groups["@"]:
        text += f" ({' / '.join(groups['@'])})"
    return text


def table(full: dict, quick: dict) -> str:
    lines = ["| JSON key | target | full run | `--quick` run |", "|---|---:|---:|---:|"]
    lines += [f"| {label} |{f' {target} ' if target else ' '}| {cell(full, keys, d)} | {cell(quick, keys, d)} |"
              for label, target, keys, d in ROWS]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    full, quick = (json.loads(Path(p).read_text()) for p in argv)
    sys.stdout.write(table(full, quick))
    return 0


if __name__ == "__main__":
    sys.exit(main())
