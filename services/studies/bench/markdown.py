"""A bench report (the JSON of `sharedctl bench --json`) as Markdown tables, for docs/performance/."""
from __future__ import annotations

import math

from .stack_run import SENSOR_LEAD_US


def _fmt(value, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:,.{digits}g}" if abs(value) < 100 else f"{value:,.0f}"
    return str(value)


def lookup(report: dict, dotted: str):
    """report["a"]["b"]… for "a.b…", or None where a part is missing."""
    node = report
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node


def render(report: dict) -> str:
    m = report.get("machine", {})
    out = [
        f"# sharedctl bench{' --quick' if report.get('quick') else ''}",   # the start time stays in the JSON
        "",
        f"Machine: {m.get('cpu')}, {m.get('cores')} cores, kernel {m.get('kernel')}, Python {m.get('python')}, "
        f"numpy {m.get('numpy')}; load average (1, 5, 15 min) before {m.get('loadavg_before')}, "
        f"after {m.get('loadavg_after')}.",
        "",
        "## Targets",
        "",
        "| figure | measured | target | met |",
        "|---|---:|---|---|",
    ]
    for key, t in report.get("targets", {}).items():
        out.append(f"| `{key}` | {_fmt(t.get('value'))} | {t.get('target')} | {_fmt(t.get('met'))} |")
    out += ["", "## Control step (µs; machine law engaged — operator-only steps and all steps beside)", "",
            "| law | median | p99 | thread-CPU median | all steps median | operator-only median |",
            "|---|---:|---:|---:|---:|---:|"]
    for law, s in (report.get("control_step_us") or {}).items():
        out.append(f"| {law} | {_fmt(s.get('median'))} | {_fmt(s.get('p99'))} | {_fmt(s.get('thread_cpu_median'))} | "
                   f"{_fmt(lookup(s, 'all.median'))} | {_fmt(lookup(s, 'operator_only.median'))} |")
    detail = report.get("control_step_detail") or {}
    if detail.get("breakdown_us"):
        out += ["", "Parts of one engaged CE step (µs, median of repeated calls):", "", "| part | µs |", "|---|---:|"]
        out += [f"| {k} | {_fmt(v)} |" for k, v in detail["breakdown_us"].items()]
    if detail.get("floors_ns"):
        out += ["", "Floors (ns per call, least batch mean):", "", "| operation | ns |", "|---|---:|"]
        out += [f"| {k.removesuffix('_ns')} | {_fmt(v)} |" for k, v in detail["floors_ns"].items()]
    if detail.get("scaling_groups"):
        out += ["", "Step against the number of constraint groups (CE, all steps):", "",
                "| groups | median µs | p99 µs | engaged fraction |", "|---:|---:|---:|---:|"]
        out += [f"| {r['groups']} | {_fmt(r['median_us'])} | {_fmt(r['p99_us'])} | {_fmt(r['engaged_fraction'])} |"
                for r in detail["scaling_groups"]]
    if detail.get("profile"):
        out += ["", "Profile (cProfile, CE along the trajectory, by own time):", "", "```", detail["profile"], "```"]
    # the third run: free-running ticks since sensor sync became the default; reports from before: --sensor-sync
    third, label = (("loop_free_running", "--no-sensor-sync") if "loop_free_running" in report
                    else ("loop_sensor_sync", "--sensor-sync"))
    out += ["", "## Loop, latency, bus, CPU", "", f"| figure | 500 Hz | 1 kHz | 500 Hz, {label} |",
            "|---|---:|---:|---:|"]
    runs = ("loop", "loop_1khz", third)
    for key in ("rate_hz", "deadline_misses", "jitter_p50_us", "jitter_p99_us", "periods_without_torque_on_bus"):
        out.append(f"| loop {key} | " + " | ".join(_fmt(lookup(report, f"{r}.{key}")) for r in runs) + " |")
    for key in ("missed", "late", "estops", "lateness_p99_us", "compute_p50_us", "compute_p99_us",
                "torque_out_p50_us", "torque_out_p99_us", "sensor_to_torque_p50_us", "sensor_to_torque_p99_us",
                "loop_cpu_p50_us", "loop_cpu_p99_us", "sensor_waits", "sensor_waits_in_vain", "misses_woke_late",
                "misses_not_run", "misses_working", "misses_working_cpu_p50_us"):
        out.append(f"| daemon {key} | " + " | ".join(_fmt(lookup(report, f"{r}.daemon.{key}")) for r in runs) + " |")
    out.append("| the drives' send jitter p50 / p99 µs | " + " | ".join(
        f"{_fmt(lookup(report, f'{r}.drives_send_jitter_us.p50'))} / "
        f"{_fmt(lookup(report, f'{r}.drives_send_jitter_us.p99'))}"
        for r in runs) + " |")
    sensor = ("latency.sensor_to_torque_us", "loop_1khz.sensor_to_torque_us", f"{third}.sensor_to_torque_us")
    out.append("| sensor → torque p50 / p99 µs | " + " | ".join(
        f"{_fmt(lookup(report, s + '.p50'))} / {_fmt(lookup(report, s + '.p99'))}" for s in sensor) + " |")
    out.append(f"| operator → torque p50 / p99 µs | {_fmt(lookup(report, 'latency.operator_to_torque_us.p50'))} / "
               f"{_fmt(lookup(report, 'latency.operator_to_torque_us.p99'))} | | "
               f"{_fmt(lookup(report, f'{third}.operator_to_torque_us.p50'))} / "
               f"{_fmt(lookup(report, f'{third}.operator_to_torque_us.p99'))} |")
    for name, what in (("default", "Zenoh's default QoS"), ("streams", "the operator stream's QoS")):
        out.append(f"| operator → torque p50 / p99 µs, {what} | "
                   f"{_fmt(lookup(report, f'latency.operator_to_torque_by_qos_us.{name}.p50'))} / "
                   f"{_fmt(lookup(report, f'latency.operator_to_torque_by_qos_us.{name}.p99'))} | | |")
    for key in ("zenoh_floor_us", "can_floor_us"):
        out.append(f"| {key.removesuffix('_us').replace('_', ' ')} p50 / p99 µs | "
                   f"{_fmt(lookup(report, f'latency.{key}.p50'))} / {_fmt(lookup(report, f'latency.{key}.p99'))} | | |")
    out.append(f"| bus load (1 Mbit/s, worst-case stuffing) | {_fmt(lookup(report, 'bus_load.fraction_1mbit'))} | "
               f"{_fmt(lookup(report, 'loop_1khz.bus_load.fraction_1mbit'))} | |")
    out.append(f"| CPU, robot + controller (fraction of one core) | "
               f"{_fmt(lookup(report, 'cpu.fraction_of_one_core'))} | "
               f"{_fmt(lookup(report, 'loop_1khz.cpu.fraction_of_one_core'))} | |")
    per = lookup(report, "cpu.per_process") or {}
    if per:
        out.append(f"| CPU per process at 500 Hz | {', '.join(f'{k} {_fmt(v)}' for k, v in per.items())} | | |")
    b = report.get("batched_sim") or {}
    floor = report.get("machine_floor")
    if floor:
        out += _floor_section(report, floor)
    out += ["", "## Batched simulator", "", "| robots | robot-steps/s | scalar steps/s | speed-up |",
            "|---:|---:|---:|---:|",
            f"| {_fmt(b.get('robots'))} | {_fmt(b.get('steps_per_s'))} | {_fmt(b.get('scalar_steps_per_s'))} | "
            f"{_fmt(b.get('speedup_vs_scalar'))} |"]
    if b.get("reason"):
        out += ["", f"Not measured: {b['reason']}"]
    r = report.get("ratios") or {}
    if r:
        out += ["", "## Ratios (same run)", "", "| ratio | value |", "|---|---:|"]
        out += [f"| {k} | {_fmt(v)} |" for k, v in r.items()]
    return "\n".join(out) + "\n"


def _frames_per_tick(report: dict):
    frames, ticks = lookup(report, "loop.daemon.frames_rx"), lookup(report, "loop.daemon.ticks")
    return frames / ticks if isinstance(frames, int) and isinstance(ticks, int) and ticks > 0 else None


def _floor_section(report: dict, floor: dict) -> list[str]:
    """The machine floor: the bare loop's own figures, and the 500 Hz loop beside them (machine_floor.py)."""
    pre = floor.get("pre_send_us", floor.get("work_us"))
    pinned = f", on CPU {floor['cpu']}" if floor.get("cpu") is not None else ""
    turns = floor.get("turns") if isinstance(floor.get("turns"), list) else []
    where = (f"on the bus, after each of the {len(turns)} controllers of the 500 Hz run, beside the same robot, "
             "listener and probes, with the amounts of work that controller reported (the last one's below)"
             if floor.get("on_bus") else "in a fresh process")
    out = ["", f"Machine floor (machine_floor.py): a bare {_fmt(floor['rate_hz'])} Hz loop {where}, "
           f"{_fmt(floor['work_us'])} µs of thread CPU per period ({_fmt(pre)} µs of it before the send), "
           f"SCHED_FIFO {'yes' if floor['realtime'] else 'no'}{pinned}, {_fmt(floor['seconds'])} s in all:", "",
           "| deadline misses (missed / late) | lateness p50 / p99 / max µs | work wall p50 / p99 / max µs | "
           "work thread CPU p50 / p99 / max µs | ticks whose work took over half a period | steal s |",
           "|---:|---:|---:|---:|---:|---:|",
           f"| {floor['deadline_misses']} ({floor['missed']} / {floor['late']}) | "
           + " | ".join(" / ".join(_fmt(floor[k][q]) for q in ("p50", "p99", "max"))
                        for k in ("lateness_us", "work_wall_us", "work_thread_cpu_us"))
           + f" | {floor['ticks_over_half_period']} | {_fmt(floor['steal_s'])} |", ""]
    if "send_jitter_us" not in floor:
        return out
    on_bus = isinstance(floor.get("bus"), dict)
    jitter_floor = (f"{_fmt(lookup(floor, 'bus.jitter_p50_us'))} / {_fmt(lookup(floor, 'bus.jitter_p99_us'))}" if on_bus
                    else f"{_fmt(floor['send_jitter_us']['p50'])} / {_fmt(floor['send_jitter_us']['p99'])}")
    rows = [
        ("deadline misses", _fmt(lookup(report, "loop.deadline_misses")), _fmt(floor["deadline_misses"])),
        ("the daemon's misses by cause: woke late / overran while not running / overran while working (their "
         "thread CPU p50 µs; CAN frames and operator messages they handled, p50; CAN frames per period, mean)",
         " / ".join(_fmt(lookup(report, f"loop.daemon.misses_{k}")) for k in ("woke_late", "not_run", "working"))
         + f" ({_fmt(lookup(report, 'loop.daemon.misses_working_cpu_p50_us'))}; "
         f"{_fmt(lookup(report, 'loop.daemon.misses_working_frames_p50'))} and "
         f"{_fmt(lookup(report, 'loop.daemon.misses_working_commands_p50'))}; {_fmt(_frames_per_tick(report))})", ""),
        ("period jitter p50 / p99 µs (torque bursts on the bus"
         + (")" if on_bus else "; the floor: its send instants)"),
         f"{_fmt(lookup(report, 'loop.jitter_p50_us'))} / {_fmt(lookup(report, 'loop.jitter_p99_us'))}", jitter_floor),
        ("wake-up lateness p99 / max µs",
         f"{_fmt(lookup(report, 'loop.daemon.lateness_p99_us'))} / "
         f"{_fmt(lookup(report, 'loop.daemon.lateness_max_us'))}",
         f"{_fmt(floor['lateness_us']['p99'])} / {_fmt(floor['lateness_us']['max'])}"),
        ("tick start → send p50 / p99 µs",
         f"{_fmt(lookup(report, 'loop.daemon.torque_out_p50_us'))} / "
         f"{_fmt(lookup(report, 'loop.daemon.torque_out_p99_us'))}",
         f"{_fmt(floor['pre_send_wall_us']['p50'])} / {_fmt(floor['pre_send_wall_us']['p99'])}"),
        ("loop thread CPU per period p50 / p99 µs",
         f"{_fmt(lookup(report, 'loop.daemon.loop_cpu_p50_us'))} / "
         f"{_fmt(lookup(report, 'loop.daemon.loop_cpu_p99_us'))}",
         f"{_fmt(floor['work_thread_cpu_us']['p50'])} / {_fmt(floor['work_thread_cpu_us']['p99'])}"),
        (f"sensor → torque p99 µs (the floor: the sensor lead, {SENSOR_LEAD_US:g} µs, + deadline → send p99)",
         _fmt(lookup(report, "latency.sensor_to_torque_us.p99")),
         _fmt(floor["deadline_to_send_us"]["p99"] + SENSOR_LEAD_US)),
        ("the guest's steal time over the run, s", _fmt(lookup(report, "cpu.steal_s")), _fmt(floor.get("steal_s"))),
    ]
    when = "in turns with it" if turns else "right after it"
    several = " (over several controllers: counts summed, p99 the worst controller's, p50 the median)" if turns else ""
    out += [f"The 500 Hz loop beside its floor (the floor ran {when}, with its amounts of work){several}:", "",
            "| figure | the daemon's loop | the bare loop |", "|---|---:|---:|"]
    out += [f"| {name} | {ours} | {bare} |" for name, ours, bare in rows]
    if turns:
        out += ["", "Turn by turn (each controller, then the bare loop for as long as that controller ran):", "",
                "| turn | misses: daemon (woke late / not running / working) | misses: bare loop | "
                "jitter p99 µs: daemon / bare loop | thread CPU per period p50 µs: daemon / bare loop | "
                "steal s: daemon's measurement window / bare loop's whole run | the daemon's first misses, s after its "
                "loop started (cause) |", "|---:|---:|---:|---:|---:|---:|---|"]
        for k, t in enumerate(turns, 1):
            d, f = t["daemon"], t["floor"]
            out.append(f"| {k} | {_fmt(d['deadline_misses'])} ({_fmt(d['misses_woke_late'])} / "
                       f"{_fmt(d['misses_not_run'])} / "
                       f"{_fmt(d['misses_working'])}) | {_fmt(f['deadline_misses'])} | {_fmt(d['jitter_p99_us'])} / "
                       f"{_fmt(f['jitter_p99_us'])} | {_fmt(d['loop_cpu_p50_us'])} / {_fmt(f['loop_cpu_p50_us'])} | "
                       f"{_fmt(d['steal_s'])} / {_fmt(f['steal_s'])} | {_miss_times(d.get('miss_times'))} |")
    return out + [""]


def _miss_times(times) -> str:
    if times is None:
        return "—"
    return ", ".join(f"{t:.2f} ({cause})" for t, cause in times) or "none"
