"""The markdown report of `sharedctl compare --report DIR`: tables, figures and what the numbers say.

Every statement about results is computed from the rows here; the fixed text only describes the
strategies and metrics as implemented (sharedctl/baselines/).
"""
from __future__ import annotations

import statistics
from pathlib import Path

from sharedctl.baselines.cbf import CbfSafetyFilter
from sharedctl.baselines.comparison import CONTROL_PERIOD
from sharedctl.baselines.mux import PriorityMux
from sharedctl.baselines.operator_link import IMPAIRED

from .figures import metrics_figure, paths_figure, signals_figure
from .price import price_section

BETTER = {  # metric: +1 when larger is better, −1 when smaller is better
    "min_margin": +1, "tracking_error": -1, "human_authority": +1, "interventions": -1,
    "control_effort": -1, "jerk_rms": -1,
}
COLUMNS = ("violations", "min_margin", "tracking_error", "time_to_goal", "human_authority", "interventions",
           "control_effort", "jerk_rms", "hands_off")


def write_report(outcomes, doc: dict, out: Path) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    rows = doc["results"]
    strategies = doc["strategies"]
    labels = list(dict.fromkeys(r["scenario"] for r in rows))
    bases = list(dict.fromkeys(r["base_scenario"] for r in rows))
    conditions = list(dict.fromkeys(r["condition"] for r in rows))
    figures = []
    fig = metrics_figure(rows, strategies, labels)
    fig.savefig(out / "metrics.png", dpi=90)
    figures.append(("metrics.png", "Every metric, every run (log scale for effort and jerk)."))
    for base in bases:
        mine = [o for o in outcomes if o.entry.scenario.name == base]
        paths_figure(mine, conditions, f"{base}: paths").savefig(out / f"paths_{base}.png", dpi=80)
        figures.append((f"paths_{base}.png", f"{base}: every strategy's path, per link condition."))
        ideal = [o for o in mine if o.condition.name == conditions[0]]
        signals_figure(ideal, f"{base} ({conditions[0]} link)").savefig(out / f"signals_{base}.png", dpi=80)
        figures.append((f"signals_{base}.png",
                        f"{base}: margin, force and overrides over time ({conditions[0]} link)."))
    text = _markdown(doc, rows, strategies, labels, figures)
    path = out / "report.md"
    path.write_text(text)
    return path


def _fmt(value) -> str:
    if value is None:
        return "—"
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, int):
        return str(value)
    if abs(value) >= 1e4 or (value != 0 and abs(value) < 1e-3):
        return f"{value:.3g}"
    return f"{value:.3f}"


def _wins(rows, strategies, labels):
    """Per metric: how many runs each strategy wins among the strategies that stayed inside."""
    wins = {m: {s: 0 for s in strategies} for m in BETTER}
    for label in labels:
        safe = [r for r in rows if r["scenario"] == label and r["violations"] == 0 and r["finite"]]
        for metric, sign in BETTER.items():
            values = [r for r in safe if r[metric] is not None]
            if not values:
                continue
            best = max(sign * r[metric] for r in values)
            for r in values:
                if sign * r[metric] >= best - 1e-12 * max(1.0, abs(best)):
                    wins[metric][r["strategy"]] += 1
    return wins


def _head_to_head(rows, labels, a: str, b: str) -> list[str]:
    table = {(r["strategy"], r["scenario"]): r for r in rows}
    lines = []
    pairs = [(table[(a, lb)], table[(b, lb)]) for lb in labels if (a, lb) in table and (b, lb) in table]
    if not pairs:
        return lines
    n = len(pairs)
    for metric, sign in BETTER.items():
        better = sum(1 for ra, rb in pairs if sign * (ra[metric] - rb[metric]) > 1e-12)
        ratios = [ra[metric] / rb[metric] for ra, rb in pairs if rb[metric] not in (0, None) and ra[metric] is not None]
        median = f"; median {a}/{b} ratio {statistics.median(ratios):.3g}" if ratios else ""
        lines.append(f"- **{metric}**: `{a}` better than `{b}` in {better} of {n} runs{median}.")
    return lines


def _share(rows, labels, a, b, metric) -> tuple[int, int]:
    """(runs where a is strictly better than b on metric, runs compared)."""
    table = {(r["strategy"], r["scenario"]): r for r in rows}
    pairs = [(table[(a, lb)], table[(b, lb)]) for lb in labels if (a, lb) in table and (b, lb) in table]
    sign = BETTER[metric]
    return sum(1 for ra, rb in pairs if sign * (ra[metric] - rb[metric]) > 1e-12), len(pairs)


def _where(rows, labels, a, b, metric) -> str:
    table = {(r["strategy"], r["scenario"]): r for r in rows}
    sign = BETTER[metric]
    return ", ".join(f"`{lb}`" for lb in labels if (a, lb) in table and (b, lb) in table
                     and sign * (table[(a, lb)][metric] - table[(b, lb)][metric]) > 1e-12)


def _reading(rows, labels) -> list[str]:
    """Plain statements, each printed only when the numbers of this run support it."""
    names = {r["strategy"] for r in rows}
    if not {"cbf", "shared"} <= names:
        return []
    out = ["", "## Reading the numbers", ""]
    better, n = _share(rows, labels, "cbf", "shared", "tracking_error")
    where = _where(rows, labels, "cbf", "shared", "tracking_error")
    if 2 * better > n:
        out.append(f"- **The CBF filter tracks the operator's wish better than the shared law** in {better} of {n} "
                   "runs. It changes the operator's force by the least amount that keeps the barrier "
                   "condition, and only along the faces' normals; the shared law hands the robot to a "
                   "machine law that tracks its own projected reference.")
    elif better:
        out.append(f"- The CBF filter tracks the operator's wish better than the shared law in {better} of {n} runs "
                   f"({where}); the shared law tracks better in the others.")
    fewer, n = _share(rows, labels, "cbf", "shared", "interventions")
    if fewer:
        out.append(f"- **The CBF filter intervenes less often** ({fewer} of {n} runs): once a constraint binds "
                   "it keeps shaping the force continuously instead of switching authority back and forth; "
                   "the shared law's Schmitt trigger takes over and hands back at least once per approach.")
    calmer, n = _share(rows, labels, "cbf", "shared", "control_effort")
    smoother, _ = _share(rows, labels, "cbf", "shared", "jerk_rms")
    if calmer or smoother:
        out.append(f"- **The CBF filter spends less force and jerks less**: effort lower in {calmer} of {n} runs, "
                   f"jerk lower in {smoother} of {n}. The shared law's machine law (12) pushes through a "
                   "barrier whose force grows like 1/x near a face and takes full authority for at least "
                   "the 0.25 s dwell, so its forces are large and switch at the control rate.")
    more, n = _share(rows, labels, "shared", "cbf", "human_authority")
    if 2 * more > n:
        out.append(f"- **The shared law leaves the operator in sole command more of the time** ({more} of {n} "
                   "runs): in its safe set u_s = u_h exactly, while the filter alters the force whenever a "
                   "constraint binds, which on an adversarial operator is most of the run.")
    elif more:
        out.append(f"- The shared law leaves the operator in sole command more of the time than the filter in "
                   f"{more} of {n} runs ({_where(rows, labels, 'shared', 'cbf', 'human_authority')}); the filter "
                   "in the others: the shared law's machine keeps authority for at least its dwell and, with the "
                   "backup-safe sets, takes it earlier on a fast approach, while the filter alters the force "
                   "only while a constraint binds.")
    wider, n = _share(rows, labels, "shared", "cbf", "min_margin")
    if wider:
        out.append(f"- The shared law keeps more room from the faces than the filter's δ in {wider} of {n} runs "
                   "(a design choice on both sides: b0 for one, δ for the other).")
    if "mux" in names:
        worse, n = _share(rows, labels, "shared", "mux", "tracking_error")
        jerkier, _ = _share(rows, labels, "cbf", "mux", "jerk_rms")
        out.append(f"- `mux` keeps the robot inside by stopping it: the operator's command is dropped while the "
                   f"hold is selected, so motion along a face is stop-and-go (the shared law tracks better "
                   f"in {worse} of {n} runs; the mux jerks more than the filter in {jerkier} of {n}).")
        table = {(r["strategy"], r["scenario"]): r for r in rows}
        stuck = [(lb, table[("mux", lb)]["tracking_error"] / table[("shared", lb)]["tracking_error"]) for lb in labels
                 if ("mux", lb) in table and ("shared", lb) in table
                 and table[("mux", lb)]["tracking_error"] > 2.0 * table[("shared", lb)]["tracking_error"]]
        if stuck:
            runs = ", ".join(f"`{lb}` ({ratio:.1f}×)" for lb, ratio in stuck)
            out.append(f"- **`mux` can get stuck at a face**: tracking error more than twice the shared law's "
                       f"in {runs}. "
                       "The hold drops the whole command, not just its part into the face: an operator whose "
                       "command keeps any component into the face (as the scripted operator pulling along x = 0 "
                       "does) re-triggers the hold within a sample of every hand-back and never slides along it.")
    impaired = [r["hands_off"] for r in rows if r["condition"] != "ideal" and r["hands_off"] is not None]
    if impaired:
        out.append(f"- Under {IMPAIRED.name} the operator was hands-off {min(impaired):.1%}–{max(impaired):.1%} of "
                   f"the time, including the first {IMPAIRED.uplink_delay * 1e3:.0f} ms before the first command "
                   "arrives: with independent losses a 0.3 s silence needs 15 losses in a row. The link "
                   "mostly adds delay and a jittery hold of the operator's command.")
    out.append("- **Model knowledge**: `mux` and `cbf` here are given the plant's true M, C, g; the shared "
               "law is not (θ̂(0) = 0). The next section gives them a wrong model.")
    return out


def _model_error(rows) -> list[str]:
    if not rows:
        return []
    out = ["", "## When the model is wrong", "",
           "`mux` and `cbf` again on the adversarial scenarios (ideal link) with nominal parameters "
           "θ̂ = s·θ instead of the true θ (s < 1: the robot is heavier than they think):", "",
           "| strategy | scenario | s | violations | min margin (m) | tracking error | interventions |",
           "|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| `{r['strategy']}` | {r['base_scenario']} | {r['theta_scale']:g} | {r['violations']} | "
                   f"{_fmt(r['min_margin'])} | {_fmt(r['tracking_error'])} | {r['interventions']} |")
    bad = [r for r in rows if r["violations"]]
    out.append("")
    for r in bad:
        out.append(f"- `{r['strategy']}` with θ̂ = {r['theta_scale']:g}θ **left the set** on {r['base_scenario']} "
                   f"({r['violations']} samples, min margin {r['min_margin']:+.3f} m).")
    if any(r["strategy"] == "cbf" and r["theta_scale"] < 1 for r in bad):
        out.append("- Why the filter fails with a light model: its constraint predicts q̈ = M̂⁻¹(u − Ĉq̇ − ĝ); "
                   "believing the robot lighter, it expects more deceleration from a braking force than the "
                   "robot delivers, brakes too little and arrives at the face too fast. A CBF filter's "
                   "guarantee is only as good as its model; the shared law needs none (θ̂(0) = 0 in every run above).")
    if not bad:
        out.append("- Neither model-based baseline left the set with these parameter errors.")
    return out


def _markdown(doc, rows, strategies, labels, figures) -> str:
    impaired = IMPAIRED
    mux, cbf = PriorityMux, CbfSafetyFilter
    out = [
        "# Shared control against the alternatives",
        "",
        f"Generated by `sharedctl compare{' --quick' if doc['quick'] else ''} --json docs/compare/results.json "
        "--report docs/compare` "
        f"(sharedctl {doc['version']}{', quick run' if doc['quick'] else ', full run'}). "
        "Every number below comes from that run; rerun the command to reproduce it (deterministic: "
        f"the loss pattern is seeded, seed {impaired.seed}).",
        "",
        "## What is compared",
        "",
        "Every strategy runs in one loop (`sharedctl/baselines/comparison.py`): sampled every "
        f"{CONTROL_PERIOD * 1e3:.0f} ms like the controller daemon, the plant integrated by RK4 at four "
        "sub-steps with the force held, and the same operator behind the same in-process link "
        "(`operator_link.py`): 50 Hz commands, deflection clipped to [−1, 1] as on the wire, newest "
        "command held, hands-off (u_h = 0) after 0.3 s of silence.",
        "",
        "| strategy | rule |",
        "|---|---|",
        "| `human` | the operator alone: u = u_h. |",
        f"| `mux` | twist_mux-style: a border monitor publishes *hold* (priority 100, timeout "
        f"{mux.hold_timeout} s) every period while the state is not SAFE by Definition 2 with the "
        "scenario's b0, b1, b2 (moving towards a face within b2 faster than f_b2, any approach within "
        "b0, or outside); otherwise the operator (priority 10) passes unchanged. Hold latches the pose "
        f"and holds it with a critically damped computed-torque PD (ω = {mux.hold_bandwidth} rad/s) on the "
        "true model. |",
        f"| `cbf` | QP safety filter: min ½\\|u − u_h\\|² s.t. ḧ_j + 2ω ḣ_j + ω² h_j ≥ 0 for every face, "
        f"h_j = −(k_jᵀq + t_j) − δ, ω = {cbf.bandwidth} rad/s, δ = {cbf.buffer} m, with the **true** M, C, g "
        "(quadprog). Unions: the polytope filtered against is kept while admissible (q inside, every "
        f"ψ_j = ḣ_j + ω h_j ≥ 0) unless another admissible one has {cbf.hysteresis} m more margin. |",
        "| `shared` | the paper's law (46) with the certainty-equivalent machine law (12), θ̂(0) = 0 "
        "(no model knowledge), bands b0/b1/b2 and 0.25 s minimum machine dwell, and the backup-safe sets "
        "(docs/safety.md §5): Definition 2 on the rows moved by the fail-safe stop's reach with the "
        "operator's command held, and the governor on the machine's force. |",
        "| `shared-nobackup` | `shared` with the scenario's `[backup] enabled = false`: the paper's loop, "
        "no speed-aware sets and no governor. |",
        "",
        f"Link conditions: `ideal` (no delay, no loss) and `{impaired.name}` ({impaired.uplink_delay * 1e3:.0f} ms "
        f"operator→robot, {impaired.downlink_delay * 1e3:.0f} ms robot→operator, {impaired.loss:.0%} of "
        "commands lost, Bernoulli).",
        "",
        "Scenarios:",
        "",
    ]
    for sc in doc["scenarios"]:
        out.append(f"- `{sc['name']}` ({sc['duration']:g} s): {sc['source']}")
    out += [
        "",
        "Metrics (`sharedctl/baselines/comparison_metrics.py`): *violations* — 2 ms samples with q "
        "outside the set; *min margin* — smallest distance inside the nearest face (m, negative "
        "outside); *tracking error* — RMS of |q − Π(q_d)|, Π the projection of the operator's true "
        f"wish onto the set; *time to goal* — first instant from which |q − Π(q_d)| ≤ {doc['goal_tolerance']:g} "
        "to the end (— : not at the end); *human authority* — share of samples with u = u_h; *interventions* — "
        "times u = u_h stopped holding; *control effort* — ∫|u|² dt; *jerk* — RMS of Δq̈/Δt per "
        "period; *hands-off* — share of samples with a stale operator.",
        "",
        "## Safety",
        "",
    ]
    for s in strategies:
        bad = [r for r in rows if r["strategy"] == s and (r["violations"] or not r["finite"])]
        if bad:
            runs = ", ".join(f"`{r['scenario']}` ({r['violations']} samples, min margin {r['min_margin']:+.2f} m)"
                             for r in bad)
            out.append(f"- `{s}` left the set in {len(bad)} of {sum(r['strategy'] == s for r in rows)} runs: {runs}.")
        else:
            worst = min(r["min_margin"] for r in rows if r["strategy"] == s)
            out.append(f"- `{s}` stayed inside in every run (smallest margin {worst * 1e3:.1f} mm).")
    out += [
        "",
        "`human` leaves whenever the operator's wish does: nothing stands between the stick and the "
        "wheels. The others stay inside by construction of their rules; the margins they keep "
        "are design choices (δ for `cbf`; where the bands trigger for `mux` and `shared`).",
        "",
        "## Where each strategy wins",
        "",
        "Runs won per metric, among the strategies that stayed inside in that run (ties count for each):",
        "",
        "| metric | " + " | ".join(f"`{s}`" for s in strategies) + " |",
        "|---|" + "---|" * len(strategies),
    ]
    wins = _wins(rows, strategies, labels)
    for metric in BETTER:
        out.append(f"| {metric} | " + " | ".join(str(wins[metric][s]) for s in strategies) + " |")
    out += ["", "`cbf` against `shared`, run by run:", ""]
    out += _head_to_head(rows, labels, "cbf", "shared")
    out += ["", "`mux` against `shared`, run by run:", ""]
    out += _head_to_head(rows, labels, "mux", "shared")
    out += _reading(rows, labels)
    out += _model_error(doc.get("model_sensitivity") or [])
    out += price_section(doc)
    out += ["", "## Results", ""]
    for label in labels:
        out += [f"### {label}", "", "| strategy | " + " | ".join(COLUMNS) + " |", "|---|" + "---|" * len(COLUMNS)]
        for r in rows:
            if r["scenario"] == label:
                out.append(f"| `{r['strategy']}` | " + " | ".join(_fmt(r[c]) for c in COLUMNS) + " |")
        out.append("")
    out += ["## Figures", ""]
    for name, caption in figures:
        out += [f"![{caption}]({name})", "", f"*{caption}*", ""]
    return "\n".join(out) + "\n"
