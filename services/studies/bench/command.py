"""`sharedctl bench [--quick] [--json OUT]`: the performance figures of docs/performance.md, in one run.

    control_step_us.{ce,nce,of}.{median,p99}          SharedController.step (control_step.py)
    loop.{rate_hz,deadline_misses,jitter_p99_us}       500 Hz over CAN with the simulated robot (stack_run.py):
                                                       3 controllers (6 in the full run) one after the other
    loop_1khz.{…}                                      the same at 1 kHz
    loop_free_running.{…}                              500 Hz with --no-sensor-sync (the default locks ticks to
                                                       the estimates)
    latency.{sensor_to_torque_us,operator_to_torque_us,zenoh_floor_us,can_floor_us}.{p50,p99}
    latency.operator_to_torque_by_qos_us.{default,streams}.{p50,p99}
                                                       the same, split by the publisher of each command: the
                                                       bench operator's pairs of commands go alternately with
                                                       Zenoh's default QoS and with the operator stream's
                                                       (REAL_TIME, BLOCK, express: services/zenoh_qos.py)
    batched_sim.{robots,steps_per_s,scalar_steps_per_s,speedup_vs_scalar}   (batched.py)
    bus_load.fraction_1mbit                            frames seen on the bus, worst-case stuffing
    cpu.fraction_of_one_core                           robot + controller at 500 Hz
    machine.{cpu,cores,kernel,python,loadavg_before,loadavg_after}
    machine_floor.{deadline_misses,lateness_us,send_jitter_us,pre_send_wall_us,work_thread_cpu_us,…}
                                                       a bare loop with the daemon's amounts of work and its CAN
                                                       I/O, after each controller of the 500 Hz run, beside the
                                                       same robot, listener and probes (machine_floor.py);
                                                       machine_floor.turns: each controller beside the loop after it

--markdown OUT writes the same as tables (docs/performance/bench.md); --from-json IN re-renders a saved run.
--quick: 15 s at 500 Hz (+ 15 s of the bare loop), 8 s at 1 kHz, shorter step trajectories (under 3 minutes); the
full run: 60 s and 20 s, plus the step's breakdown, floors, profile and scaling with the number of groups.
Targets are reported, never enforced: timing depends on the machine and its load.
"""
from __future__ import annotations

import importlib
import json
import math
import os
import platform
import time
from pathlib import Path

from . import control_step, stack_run
from .markdown import lookup

TURNS, QUICK_TURNS = 6, 3   # controllers run in turn with the bare loop in the 500 Hz run (full, --quick)

TARGETS = {
    "control_step_us.ce.median": ("≤", 50.0),
    "loop.deadline_misses": ("≤", 0),
    "loop.jitter_p99_us": ("≤", 300.0),
    "latency.sensor_to_torque_us.p99": ("≤", 1000.0),
    "batched_sim.steps_per_s": ("≥", 1_000_000),
    "batched_sim.speedup_vs_scalar": ("≥", 50.0),
    "bus_load.fraction_1mbit": ("≤", 0.5),
}


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("bench",
                              help="measure step cost, loop timing, latency, bus load, CPU and the batched simulator")
    p.add_argument("--quick", action="store_true", help="shorter runs (under 3 minutes)")
    p.add_argument("--json", metavar="OUT", help="write the figures as JSON to OUT")
    p.add_argument("--markdown", metavar="OUT", help="write the figures as Markdown tables to OUT")
    p.add_argument("--from-json", metavar="IN",
                   help="no measurement: render IN (a --json report) as the table / Markdown")
    p.add_argument("--skip-stack", action="store_true", help="no processes: only the step and the batched simulator")
    p.set_defaults(handler=run)


def machine() -> dict:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "kernel": platform.release(), "python": platform.python_version(),
            "numpy": _version("numpy"), "loadavg_before": _loadavg()}


def _version(name: str) -> str:
    try:
        return importlib.import_module(name).__version__
    except (ImportError, AttributeError):   # not installed, or no __version__
        return "?"


def _loadavg() -> list[float] | None:
    try:
        return [float(x) for x in Path("/proc/loadavg").read_text().split()[:3]]
    except OSError:
        return None


def batched(quick: bool) -> dict:
    try:
        module = importlib.import_module("sharedctl.services.studies.bench.batched")
    except ImportError as exc:
        return {"robots": None, "steps_per_s": None, "scalar_steps_per_s": None, "speedup_vs_scalar": None,
                "reason": f"the batched simulator's benchmark is not available: {exc}"}
    try:
        return module.measure_batched(quick)
    except Exception as exc:  # noqa: BLE001 — one failed section must not lose the others
        return {"robots": None, "steps_per_s": None, "scalar_steps_per_s": None, "speedup_vs_scalar": None,
                "reason": f"measure_batched failed: {type(exc).__name__}: {exc}"}


def _stack_run(*args, progress=print, **kwargs) -> dict:
    """`stack_run.run`, once more with fresh ports if a loopback port picked for it was taken before its
    listener bound it (another process's outgoing connection can draw the same ephemeral port)."""
    try:
        return stack_run.run(*args, **kwargs)
    except Exception as exc:  # zenoh.ZError is not importable without zenoh
        if "Address already in use" not in str(exc):
            raise
        progress(f"a loopback port was taken before the stack bound it ({type(exc).__name__}); again with new ports …")
        return stack_run.run(*args, **kwargs)


def collect(quick: bool, skip_stack: bool = False, progress=print) -> dict:
    report: dict = {"quick": quick, "machine": machine(), "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    progress("control step …")
    report["control_step_us"] = control_step.measure(quick)
    if not quick:
        progress("step breakdown, floors, profile, scaling …")
        report["control_step_detail"] = {
            "breakdown_us": control_step.breakdown(), "floors_ns": control_step.floors(),
            "profile": control_step.profile_summary(), "scaling_groups": control_step.scaling(),
        }
    if not skip_stack:
        seconds, seconds_1k = (15.0, 8.0) if quick else (60.0, 20.0)
        turns = QUICK_TURNS if quick else TURNS
        progress(f"stack at 500 Hz for {seconds:g} s: {turns} controllers in turn with the bare loop on the same bus …")
        run500 = _stack_run(500.0, seconds, progress=progress, turns=turns, floor=True, compare_qos=True)
        report["machine_floor"] = run500.get("machine_floor")
        progress(f"stack at 1 kHz for {seconds_1k:g} s …")
        run1k = _stack_run(1000.0, seconds_1k, probes=False, progress=progress)
        report["loop"] = run500["loop"]
        report["latency"] = run500["latency"]
        report["bus_load"] = run500["bus_load"]
        report["cpu"] = run500["cpu"]
        report["loop_1khz"] = dict(run1k["loop"], sensor_to_torque_us=run1k["latency"]["sensor_to_torque_us"],
                                   bus_load=run1k["bus_load"], cpu=run1k["cpu"])
        progress(f"stack at 500 Hz, free-running ticks (--no-sensor-sync), for {seconds_1k:g} s …")
        free = _stack_run(500.0, seconds_1k, probes=False, controller_args=("--no-sensor-sync",), progress=progress)
        report["loop_free_running"] = dict(free["loop"], sensor_to_torque_us=free["latency"]["sensor_to_torque_us"],
                                           operator_to_torque_us=free["latency"]["operator_to_torque_us"])
        report["stack"] = {name: {k: r.get(k) for k in ("processes", "robot_priority", "cpus", "log_dir")}
                           for name, r in (("500hz", run500), ("1khz", run1k), ("500hz_free_running", free))}
    progress("batched simulator …")
    report["batched_sim"] = batched(quick)
    report["machine"]["loadavg_after"] = _loadavg()
    report["ratios"] = ratios(report)
    report["targets"] = check_targets(report)
    return report


def _over_values(x, y):
    ok = all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in (x, y))
    return x / y if ok else None


def ratios(report: dict) -> dict:
    """Figures over the floor they stand on, measured in the same run (None where one is missing)."""
    def over(a, b):
        return _over_values(lookup(report, a), lookup(report, b))

    return {
        "sensor_to_torque_over_can_floor_p50": over("latency.sensor_to_torque_us.p50", "latency.can_floor_us.p50"),
        "operator_to_torque_over_zenoh_floor_p50": over("latency.operator_to_torque_us.p50",
                                                        "latency.zenoh_floor_us.p50"),
        "ce_step_over_nce_step": over("control_step_us.ce.median", "control_step_us.nce.median"),
        "ce_step_over_ce_step_without_backup": over("control_step_us.ce.median",
                                                    "control_step_us.ce.without_backup.median"),
        "of_step_over_ce_step": over("control_step_us.of.median", "control_step_us.ce.median"),
        "ce_step_in_numpy_calls": over("control_step_us.ce.median",
                                       "control_step_detail.floors_ns.numpy_ufunc_3_ns") and
        over("control_step_us.ce.median", "control_step_detail.floors_ns.numpy_ufunc_3_ns") * 1e3,
        "ce_step_over_period_500hz": (lookup(report, "control_step_us.ce.median") or math.nan) / 2000.0,
        "loop_misses_over_machine_floor_misses": over("loop.deadline_misses", "machine_floor.deadline_misses"),
        "loop_jitter_over_machine_floor_jitter_p99": over("loop.jitter_p99_us", "machine_floor.send_jitter_us.p99"),
        "torque_out_over_machine_floor_pre_send_p99": over("loop.daemon.torque_out_p99_us",
                                                           "machine_floor.pre_send_wall_us.p99"),
        "sensor_to_torque_over_machine_floor_p99": _over_values(
            lookup(report, "latency.sensor_to_torque_us.p99"),
            stack_run.SENSOR_LEAD_US + (lookup(report, "machine_floor.deadline_to_send_us.p99") or math.nan)),
        "loop_1khz_rate_over_target": (lookup(report, "loop_1khz.rate_hz") or math.nan) / 1000.0,
    }


def check_targets(report: dict) -> dict:
    out = {}
    for key, (op, bound) in TARGETS.items():
        value = lookup(report, key)
        ok = None
        if isinstance(value, (int, float)) and math.isfinite(value):
            ok = value <= bound if op == "≤" else value >= bound
        out[key] = {"value": value, "target": f"{op} {bound:g}", "met": ok}
    return out


def table(report: dict):
    from rich.table import Table

    t = Table(title=f"sharedctl bench{' --quick' if report['quick'] else ''} · "
                    f"load {report['machine'].get('loadavg_before')} → {report['machine'].get('loadavg_after')}")
    t.add_column("figure")
    t.add_column("value", justify="right")
    t.add_column("target")
    t.add_column("met")

    def fmt(v):
        if v is None:
            return "—"
        if isinstance(v, float):
            return f"{v:,.3g}" if abs(v) < 10 else f"{v:,.0f}"
        return str(v)

    rows = [f"control_step_us.{law}.{s}" for law in control_step.LAWS for s in ("median", "p99")]
    rows += ["loop.rate_hz", "loop.deadline_misses", "loop.jitter_p99_us", "loop_1khz.rate_hz",
             "loop_1khz.deadline_misses", "loop_1khz.jitter_p99_us", "loop_free_running.deadline_misses",
             "loop_free_running.jitter_p99_us", "loop_free_running.sensor_to_torque_us.p50",
             "loop_free_running.sensor_to_torque_us.p99", "loop.drives_send_jitter_us.p99",
             "machine_floor.deadline_misses", "machine_floor.send_jitter_us.p99",
             "machine_floor.deadline_to_send_us.p99", "machine_floor.lateness_us.p99", "machine_floor.work_wall_us.p99",
             "machine_floor.work_wall_us.max"]
    rows += [f"latency.{k}.{s}"
             for k in ("sensor_to_torque_us", "operator_to_torque_us", "zenoh_floor_us", "can_floor_us")
             for s in ("p50", "p99")]
    rows += ["batched_sim.robots", "batched_sim.steps_per_s", "batched_sim.scalar_steps_per_s",
             "batched_sim.speedup_vs_scalar", "bus_load.fraction_1mbit", "cpu.fraction_of_one_core"]
    targets = report.get("targets", {})
    for key in rows:
        target = targets.get(key, {})
        met = target.get("met")
        t.add_row(key, fmt(lookup(report, key)), target.get("target", ""),
                  "" if key not in targets else ("[green]yes" if met else "[red]no" if met is False else "—"))
    return t


def run(args) -> int:
    from rich.console import Console

    console = Console(stderr=False)
    if args.from_json:
        report = json.loads(Path(args.from_json).read_text())
    else:
        report = collect(args.quick, args.skip_stack, progress=lambda text: console.print(f"[dim]{text}"))
    console.print(table(report))
    reason = lookup(report, "batched_sim.reason")
    if reason:
        console.print(f"[yellow]batched_sim: {reason}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(finite_or_null(report), indent=2, default=str, allow_nan=False) + "\n")
        console.print(f"[dim]wrote {args.json}")
    if args.markdown:
        from .markdown import render

        Path(args.markdown).parent.mkdir(parents=True, exist_ok=True)
        Path(args.markdown).write_text(render(finite_or_null(report)))
        console.print(f"[dim]wrote {args.markdown}")
    return 0


def finite_or_null(value):
    """The report with NaN/inf (a figure that could not be measured) as null, so the JSON is strict."""
    if isinstance(value, dict):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_null(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
