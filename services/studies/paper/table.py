"""The paper command's table: one record per scenario and law (summary.json), and summary.md rendered from it.

Every number is a `sharedctl.metrics` function of the run's trace; nothing here computes a metric.
The Markdown is rendered from the JSON document (never parsed back), including the sentence that
answers Remark 3 (does NCE estimate θ better than CE?) with the runs' θ errors.
"""
from __future__ import annotations

import math

from sharedctl.metrics import handover, machine_authority_time, peak_norm, rms_norm, share_above, summarize

from sharedctl.services.robot.plant import RobotSimConfig


def wheel_torque_limit(scenario) -> float:
    """The simulated robot's per-wheel drive limit (N·m) for this scenario: its `[robot_sim]` torque_limit."""
    return RobotSimConfig.from_table(scenario.data.get("robot_sim")).torque_limit


def run_record(scenario, kind: str, law: str, trace, loop) -> dict:
    """One row of the table: the `sharedctl sim --json` summary and the input, torque and adaptation figures."""
    dt = scenario.dt
    record = {"scenario": scenario.name, "controller": kind, "law": law, **summarize(trace, dt),
              "u_s_peak": peak_norm(trace.u_s), "u_s_rms": rms_norm(trace.u_s),
              "wheel_torque_peak": None, "wheel_torque_limit": None, "wheel_torque_over_limit": None,
              "machine_authority_time": machine_authority_time(trace, dt)}
    if hasattr(loop.model, "wheel_torques"):   # trace.tau = B(ψ)⁻¹ u_s, the wheel torques
        limit = wheel_torque_limit(scenario)
        record.update(wheel_torque_peak=handover(trace)["peak_wheel_torque"], wheel_torque_limit=limit,
                      wheel_torque_over_limit=share_above(trace.tau, limit))
    record.update(parameter_names=list(loop.model.parameter_names),
                  theta_true=[float(x) for x in loop.model.theta], dt=dt)
    return record


def _number(x, digits=4) -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{digits}g}"


def _share(x) -> str:
    return "–" if x is None else f"{x:.3f}"


COLUMNS = (  # (heading, cell of a record)
    ("scenario", lambda r: r["scenario"]),
    ("law", lambda r: r["controller"]),
    ("violations", lambda r: str(r["violations"])),
    ("min margin (m)", lambda r: _number(r["min_margin"])),
    ("tracking RMS (m)", lambda r: _number(r["tracking_rmse"])),
    ("final error (m)", lambda r: _number(r["final_error"])),
    ("θ error", lambda r: _number(r["theta_error"], 3)),
    ("peak \\|u_s\\|", lambda r: _number(r["u_s_peak"])),
    ("RMS \\|u_s\\|", lambda r: _number(r["u_s_rms"])),
    ("peak \\|τ\\| (N·m)", lambda r: _number(r["wheel_torque_peak"])),
    ("τ limit (N·m)", lambda r: _number(r["wheel_torque_limit"])),
    ("over limit", lambda r: _share(r["wheel_torque_over_limit"])),
    ("switches", lambda r: str(r["switches"])),
    ("transparency", lambda r: _share(r["transparency"])),
    ("law_share", lambda r: _share(r["law_share"])),
    ("machine time (s)", lambda r: _number(r["machine_authority_time"], 3)),
    ("finite", lambda r: "yes" if r["finite"] else "NO"),
    ("steps", lambda r: str(r["steps"])),
)


def metrics_table(records: list[dict]) -> str:
    rows = ["| " + " | ".join(h for h, _ in COLUMNS) + " |", "|" + "|".join("---" for _ in COLUMNS) + "|"]
    rows += ["| " + " | ".join(cell(r) for _, cell in COLUMNS) + " |" for r in records]
    return "\n".join(rows)


def remark_3(records: list[dict]) -> list[str]:
    """Per scenario, the θ errors of ce and nce at the end, and which is lower (from the records)."""
    lines = []
    for scenario in dict.fromkeys(r["scenario"] for r in records):
        runs = {r["controller"]: r for r in records if r["scenario"] == scenario}
        if "ce" not in runs or "nce" not in runs:
            lines.append(f"- {scenario}: not answered (ce and nce did not both run).")
            continue
        ce, nce = runs["ce"]["theta_error"], runs["nce"]["theta_error"]
        if ce is None or nce is None:
            lines.append(f"- {scenario}: not answered (θ unknown or a run not finite).")
            continue
        verdict = ("nce's is lower" if nce < ce else "ce's is lower" if ce < nce else "they are equal")
        lines.append(f"- {scenario}: θ error at the end: ce {ce:.3g}, nce {nce:.3g} — {verdict}; θ̂ adapted "
                     f"during {runs['ce']['machine_authority_time']:.3g} s (ce) and "
                     f"{runs['nce']['machine_authority_time']:.3g} s (nce) of full machine authority, "
                     f"in {runs['ce']['duration']:g} s.")
    return lines


def law_notes(records: list[dict]) -> list[str]:
    """Say plainly when a run's configured law never ran while the machine acted (`law_share` 0)."""
    notes = [f"- {r['scenario']} {r['controller']}: the machine acted, but never through this configuration's "
             f"own law (`law_share` 0): every machine sample ran a fallback law." for r in records
             if r.get("law_share") == 0.0]
    return notes + [""] if notes else []


def summary_markdown(document: dict, command: str) -> str:
    """summary.md from the summary.json document; `command` is the command line that made it."""
    records, figures, ok = document["runs"], document["figures"], document["ok"]
    durations = ", ".join(f"{s} {d:g} s" for s, d in dict.fromkeys((r["scenario"], r["duration"]) for r in records))
    names = ", ".join(records[0]["parameter_names"]) if records else ""
    limit = next((r["wheel_torque_limit"] for r in records if r["wheel_torque_limit"] is not None), None)
    lines = [
        "# Section 5 of Tang & Sun (2025), reproduced",
        "",
        f"Generated by `{command}`: omnidirectional robot, shared control with the scripted operator,",
        f"RK4 at dt = {records[0]['dt'] * 1e3:g} ms; {durations}." if records else "",
        "",
        "## Configurations",
        "",
        *[f"- {kind}: {law}" for kind, law in document["configurations"].items()],
        "",
        "## Metrics",
        "",
        metrics_table(records),
        "",
        "- violations: samples with q outside Q_a; min margin: min over time of the best region's smallest slack;",
        "- tracking RMS / final error: |q − q_r| against the machine's projected reference q_r;",
        f"- θ error: |θ̂ − θ|/|θ| at the end, θ = [{names}], θ̂(0) = 0;",
        "- |u_s|: the generalised force applied (N and N·m in one norm); |τ|: the largest single wheel torque "
        "B(ψ)⁻¹u_s, against the simulated drives' limit"
        + (f" ({limit:g} N·m)" if limit is not None else "") + "; over limit: share of samples above it "
        "(the simulator does not clamp; the daemon scales such torques down);",
        "- switches: human ↔ machine authority changes; transparency: share of the samples with the true state in "
        "O_s in which u_s = u_h;",
        "- law_share: share of the machine-authority samples whose u_f came from the configuration's own law "
        "(`sharedctl.metrics.law_share`);",
        "- machine time: time with full machine authority (u_s = u_f), the only time θ̂ adapts (docs/control.md §6).",
        "",
        *law_notes(records),
        "## Remark 3: does NCE estimate θ better than CE?",
        "",
        *remark_3(records),
        "",
        f"Result: {'every run stayed inside Q_a and finite.' if ok else '**a run left Q_a or diverged.**'}",
        "",
        "## Figures",
        "",
    ]
    lines += [f"- `{f['file']}` — {f['caption']}." for f in figures]
    return "\n".join(lines) + "\n"
