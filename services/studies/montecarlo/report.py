"""The Monte-Carlo's report: README.md (the verdict, the bound per family, the counterexamples and how
to replay them), the envelope maps as figures, and every counterexample as a scenario file.

Maps (matplotlib, Agg): CAN delay × frame loss (families `can` and `beyond`), fault instant ×
the speed at which the robot closed on its nearest face at that instant (`kill`, `hang`), and the
true mass against the controller's (`mismatch`) — each run a dot coloured by its minimum margin,
violations as red crosses. Counterexamples: `counterexamples/run-N.toml` (a scenario `sharedctl sim`
and `sharedctl demo --scenario` take) with the `--fault` specs that replay its faults.
"""
from __future__ import annotations

from pathlib import Path


def write_report(summary: dict, results: list[dict], out_dir: Path) -> list[Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    files = [p for p in (_map(results, ("can", "beyond"), "can_delay_ms", "can_loss", "CAN delay each way (ms)",
                              "CAN frame loss", out_dir / "can_delay_loss.png"),
                         _map(results, ("kill", "hang"), "fault_t", "approach_speed", "fault instant (s)",
                              "closing speed on the nearest face at the fault (m/s)",
                              out_dir / "fault_instant_speed.png"),
                         _map(results, ("mismatch",), "mismatch_m1", None, "true m1 / nominal m1", "min margin (m)",
                              out_dir / "mismatch.png")) if p is not None]
    replays = _counterexamples(summary["counterexamples"], out_dir / "counterexamples")
    md = out_dir / "README.md"
    md.write_text(markdown(summary, [p.name for p in files], replays))
    return [md, *files, *replays]


def markdown(summary: dict, plots: list[str], replays: list[Path]) -> str:
    lines = ["# Fault Monte-Carlo", ""]
    if summary.get("command"):
        lines += ["```", summary["command"], "```", ""]
    inside = summary["violations_inside_envelope"]
    lines += [f"{summary['runs']} runs of {summary['duration_s']:g} s at {summary['control_rate_hz']:.0f} Hz "
              f"(seed {summary.get('seed')}, {summary.get('chunk_runs')} runs per chunk, {summary.get('workers')} "
              f"workers, {summary['runs_per_s']:.0f} runs/s). **{summary['violations']} violations, {inside} of them "
              f"inside the guarantee's envelope.** Worst margin {summary['min_margin']:.4f} m.", "",
              "Each run is the batched fault loop (services/studies/montecarlo/loop.py: the sampled shared "
              "controller, the CAN link, the drives' watchdogs and brakes, the operator link, the robot's true "
              "plant) on a random set, law, initial state, operator and faults (cases.py). `upper_95` is the "
              "one-sided 95 % Clopper–Pearson upper bound on the probability that a run of the family leaves the "
              "set: with k violations in n runs, beta.ppf(0.95, k + 1, n − k).", "",
              "| family | inside the envelope | runs | violations | upper_95 | min margin (m) | estops |",
              "|---|---|---:|---:|---:|---:|---:|"]
    for f in summary["families"]:
        lines.append(f"| `{f['family']}` | {'yes' if f['inside_envelope'] else 'no'} | {f['runs']} | "
                     f"{f['violations']} | {f['upper_95']:.2e} | {f['min_margin']:.4f} | {f['estops']} |")
    lines.append("")
    for name in plots:
        lines += [f"![{name}]({name})", ""]
    lines += _calibration(summary.get("calibration"))
    lines += _replays(summary.get("replays"))
    lines += ["## Counterexamples", ""]
    if not replays:
        lines += ["None: no run left the set, so none beyond the envelope to replay in the processes.", ""]
    for case, path in zip(summary["counterexamples"], replays):
        faults = " ".join(f"--fault {spec}" for spec in case["faults"])
        lines += [f"- run {case['run']} (`{case['family']}`, {case['law']}, min margin {case['min_margin']:.4f} m): "
                  f"`sharedctl demo --scenario {path.parent.name}/{path.name} {faults}`"]
    return "\n".join(lines) + "\n"


def _calibration(calibration: dict | None) -> list[str]:
    if not calibration:
        return []
    lines = ["## Calibration against the real processes", "",
             f"The matched cases of `{calibration['campaign']}` (real `sharedctl demo` runs judged on the simulator's "
             "ground truth; services/studies/montecarlo/calibration.py says which match and the classes), run "
             "again on the batched model:", "",
             "| class | cases | agree | tolerance (m) | largest difference (m) | disagree |",
             "|---|---:|---:|---:|---:|---|"]
    for kind, c in calibration["classes"].items():
        lines.append(f"| {kind} | {c['cases']} | {c['agree']} | {c['tolerance_m']} | {c['max_abs_difference_m']:.4f} | "
                     f"{', '.join(f'`{_cell(i)}`' for i in c['disagree']) or '—'} |")
    lines += ["", "| case | class | ground truth (m) | model (m) | difference (m) |", "|---|---|---:|---:|---:|"]
    for e in calibration["table"]:
        lines.append(f"| `{_cell(e['id'])}` | {e['class']} | {e['ground_truth']:.4f} | {e['model']:.4f} | "
                     f"{e['difference']:+.4f}{'' if e['agrees'] else ' ✗'} |")
    return lines + [""]


def _cell(text: str) -> str:
    """`text` inside a markdown table cell (a case id holds `|`)."""
    return text.replace("|", "\\|")


def _replays(rows: list[dict] | None) -> list[str]:
    if not rows:
        return []
    lines = ["## Counterexamples beyond the envelope, replayed in the real processes", "",
             "Each run drawn again from its chunk and run once as `sharedctl demo --scenario run-N.toml --fault …`, "
             "judged on the simulator's ground truth:", "",
             "| run | family | law | faults | model min margin (m) | real min margin (m) | real violations | "
             "real estops | error |", "|---:|---|---|---|---:|---:|---:|---:|---|"]
    for r in rows:
        real = "—" if r["real_min_margin"] is None else f"{r['real_min_margin']:.4f}"
        lines.append(f"| {r['run']} | `{r['family']}` | {r['law']} | {' '.join(r['faults'])} | "
                     f"{r['model_min_margin']:.4f} | {real} | {r['real_violations']} | {r['real_estops']} | "
                     f"{r['error'] or ''} |")
    return lines + [""]


def _counterexamples(cases: list[dict], folder: Path) -> list[Path]:
    out = []
    for case in cases:
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"run-{case['run']}.toml"
        path.write_text(scenario_toml(case["scenario"], case["faults"]))
        out.append(path)
    return out


def scenario_toml(data: dict, faults: list[str]) -> str:
    """The scenario mapping (cases.scenario_data's keys) as TOML; the fault specs as a comment."""
    def value(v):
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(float(v)) if isinstance(v, float) else str(v)

    lines = ["# A counterexample of `sharedctl faults montecarlo`; replay its faults with:",
             "#   " + " ".join(f"--fault {spec}" for spec in faults)]
    lines += [f"{k} = {value(v)}" for k, v in data.items() if not isinstance(v, (dict, list)) or k == "x"]
    for key, table in data.items():
        if isinstance(table, dict):
            lines += ["", f"[{key}]", *(f"{k} = {value(v)}" for k, v in table.items())]
        elif isinstance(table, list) and table and isinstance(table[0], dict):
            for entry in table:
                lines += ["", f"[[{key}]]", *(f"{k} = {value(v)}" for k, v in entry.items())]
    return "\n".join(lines) + "\n"


def _map(results, families, x_key, y_key, x_label, y_label, path: Path):
    rows = [r for r in results if r["family"] in families]
    xs, ys, margins, bad = [], [], [], []
    for r in rows:
        x = r["draws"].get(x_key)
        if x is None:
            continue
        y = r["min_margin"] if y_key is None else (r["approach_speed"] if y_key == "approach_speed"
                                                   else r["draws"].get(y_key))
        for xi, yi, m, v in zip(x, y, r["min_margin"], r["violated"]):
            xs.append(xi), ys.append(yi), margins.append(m), bad.append(v)
    if not xs:
        return None
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    xs, ys, margins, bad = map(np.asarray, (xs, ys, margins, bad))
    fig, ax = plt.subplots(figsize=(7, 4.5))
    sc = ax.scatter(xs[~bad], ys[~bad], c=margins[~bad], s=4, cmap="viridis", rasterized=True)
    if bad.any():
        ax.scatter(xs[bad], ys[bad], marker="x", color="red", s=20, label="left the set")
        ax.legend(loc="best")
    fig.colorbar(sc, ax=ax, label="min margin (m)")
    ax.set_xlabel(x_label)
    ax.set_ylabel(y_label)
    ax.set_title(", ".join(families) + f": {xs.size} runs")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
