"""The fault campaign's report: a markdown page and its plots, written from the campaign's JSON.

* `margin_heatmap.png` — min ground-truth margin of the adversarial wall run over operator
  latency × loss (the operator → controller stream).
* `margin_by_family.png` — every run's min margin, one column per fault family, violations in red.
* `actuation_loss.png` — min margin of the controller kill / hang / CAN bus-off / estop runs against
  the speed toward the face when the fault fired, with the forecast from the run's ground truth at
  that instant (stopping.forecast_at).
Matplotlib with the Agg backend; nothing is shown.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

GRID_KEYS = ("operator.delay_ms", "operator.loss")


def _fmt(value, digits=3) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return "–" if not math.isfinite(value) else f"{value:.{digits}f}"
    return str(value)


def _injected(row: dict, width: int = 70) -> str:
    inj = row.get("injected")
    if not inj:
        return ""
    text = json.dumps(inj, separators=(",", ":"), default=str)
    return (text[: width - 1] + "…") if len(text) > width else text


def _missed(row: dict) -> str:
    host = row.get("host") or {}
    steps = host.get("robot_physics_steps")
    return f"{100 * host.get('robot_missed_ticks', 0) / steps:.0f} %" if steps else "–"


def _fired(row: dict) -> str:
    """When the row's process faults actually went out, on the run's clock (s)."""
    times = [f["done_at"] for f in (row.get("fired") or {}).values() if f.get("done_at") is not None]
    return " ".join(f"{t:.3f}" for t in times) or "–"


def grid_cells(rows: list[dict], scenario: str = "adversarial_wall") -> dict[tuple[float, float], float]:
    """{(delay_ms, loss): worst min margin} over the runs with only operator delay/loss faults."""
    cells: dict[tuple[float, float], float] = {}
    for r in rows:
        if r["scenario"] != scenario or r.get("outcome") in ("error", "not exercised") or r["min_margin"] is None:
            continue
        if r["controller"] in ("nce", "of"):
            continue
        values = {}
        for spec in r["faults"]:
            key, _, value = spec.partition("=")
            if key not in GRID_KEYS:
                break
            values[key] = float(value)
        else:
            key = (values.get("operator.delay_ms", 0.0), values.get("operator.loss", 0.0))
            cells[key] = min(cells.get(key, math.inf), r["min_margin"])
    return cells


def write_report(result: dict, out_dir: Path, title: str = "Fault campaign") -> list[Path]:
    """Write README.md and the plots into `out_dir`; returns the files written."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = result["rows"]
    files = [p for p in (_heatmap(rows, out_dir / "margin_heatmap.png"),
                         _by_family(rows, out_dir / "margin_by_family.png"),
                         _actuation(rows, out_dir / "actuation_loss.png"),
                         _stopping(out_dir / "stopping_distance.png")) if p is not None]
    md = out_dir / "README.md"
    md.write_text(markdown(result, [p.name for p in files], title))
    return [md, *files]


def markdown(result: dict, plots: list[str], title: str = "Fault campaign") -> str:
    rows = result["rows"]
    lines = [f"# {title}", ""]
    # the run's start time stays in the JSON: the report is reference, not a diary
    meta = [f"{k}: {result[k]}" for k in ("command", "host", "load_before", "load_after") if k in result]
    if meta:
        lines += ["```", *meta, "```", ""]
    verdict = ("**0 ground-truth violations.**" if result["violating_runs"] == 0 else
               f"**{result['violating_runs']} of {result['runs']} runs left the admissible set** "
               f"({result['documented_violating_runs']} explained by the documented limit, "
               f"{len(result['unexpected_violations'])} unexpected).")
    lines += [f"{result['runs']} runs, {result['wall_seconds']:.0f} s of runs; {verdict} "
              f"Worst ground-truth margin {_fmt(result['min_margin'])} m; {result['estop_runs']} runs with an "
              f"emergency stop, {len(result.get('not_exercised', []))} of them before the run's start "
              f"(not exercised: the robot never moved); {len(result['errors'])} runs without a usable measurement.", ""]
    if result.get("overloaded_runs"):
        lines += [f"The host could not keep real time in {result['overloaded_runs']} runs (the robot simulator's loop "
                  f"missed more than half of its physics ticks; `host` in each row); "
                  f"{len(result.get('overload_violations', []))} violations happened in such runs.", ""]
    if result.get("note"):
        lines += [result["note"], ""]
    lines += ["Each run is `sharedctl demo --scenario S --duration D --fault … --headless --no-reference`, judged on "
              "the simulator's ground truth (`violations`: ground-truth samples outside the set; `min_margin`: "
              "the smallest distance to a face, m). Fault times are on the run's clock (t = 0: the operator "
              "granted the lease, as the controller reports it); `fired` is when each fault actually went out. "
              "A violation is documented only if a forecast — from the run's ground truth at that instant, "
              "or the in-process loop for a short hang or a CAN delay — says it must happen; a host that "
              "could not keep real time is reported, never an excuse. The safety policy and the "
              "stopping-distance analysis are in [docs/safety.md](../safety.md).", ""]
    for name in plots:
        lines += [f"![{name}]({name})", ""]
    lines += ["## By fault family", "",
              "| family | runs | violating | estop | not exercised | no data | min margin (m) |",
              "|---|---:|---:|---:|---:|---:|---:|"]
    for fam, f in sorted(result["families"].items()):
        lines.append(f"| `{fam}` | {f['runs']} | {f['violating_runs']} | {f['estop_runs']} | "
                     f"{f.get('not_exercised', 0)} | {f['errors']} | {_fmt(f['min_margin'])} |")
    lines += _intruders(rows)
    bad = [r for r in rows if r["violations"]]
    lines += ["", "## Violations", ""]
    if not bad:
        lines += ["None.", ""]
    for r in bad:
        fc = r.get("forecast") or r.get("estop_forecast") or r.get("delay_forecast") or {}
        lines.append(f"* `{r['id']}`: {r['violations']} samples outside, first at {_fmt(r['first_violation_t'], 2)} s, "
                     f"min margin {_fmt(r['min_margin'])} m; "
                     + (f"forecast: speed {_fmt(fc.get('speed'), 2)} m/s at {_fmt(fc.get('t_fault'), 3)} s, "
                        f"margin {_fmt(fc.get('margin'))} m, "
                        f"braking to {_fmt(fc.get('min_margin'))} m; " if "speed" in fc else
                        f"in-process forecast {_fmt(fc.get('best_min_margin'))} m; " if fc else "")
                     + (f"host overloaded ({_missed(r)} of the robot's ticks missed); " if r.get("overloaded") else "")
                     + (r["explained"] or "**not forecast: unexpected**"))
    lines += ["", "## Every run", "",
              "| # | scenario | faults | fired (s) | outcome | viol. | min margin (m) | estops | forecast margin "
              "| robot ticks missed | injected | wall (s) |",
              "|---:|---|---|---|---|---:|---:|---:|---:|---:|---|---:|"]
    for i, r in enumerate(rows):
        law = f" [{r['controller']}]" if r.get("controller") in ("nce", "of") else ""
        fc = (r.get("forecast") or r.get("delay_forecast") or {})
        fc = fc.get("min_margin") if "speed" in fc else fc.get("best_min_margin")
        lines.append(f"| {i} | {r['scenario']}{law} | {' '.join(f'`{f}`' for f in r['faults']) or '—'} | "
                     f"{_fired(r)} | {r['outcome']} | {r['violations']} | {_fmt(r['min_margin'])} | {r['estops']} | "
                     f"{_fmt(fc)} | {_missed(r)} | {_injected(r)} | {_fmt(r['wall_seconds'], 1)} |")
    lines.append("")
    return "\n".join(lines)


INTRUSION_KEYS = ("restart_at", "reboot_at", "intruder_at", "flood_at", "evict_at")


def _intruders(rows: list[dict]) -> list[str]:
    """Restarts, drive reboots, other CAN masters, floods, replays and the secured stack: what the controller
    made of each (docs/security.md)."""
    mine = [r for r in rows if r["family"].startswith("secure:")
            or any(f.split("=")[0].endswith(INTRUSION_KEYS) for f in r["faults"])]
    if not mine:
        return []
    lines = ["", "## Intruders, restarts and bad days", "",
             "What the (last) controller said of each run: how it started, its mode at the end, another CAN "
             "master's frames it saw, the operator messages it refused; ground-truth outcome and margin as above.",
             "", "| run | outcome | min margin (m) | controller start | end mode | arming refused | foreign CAN "
             "frames | refused operator messages | intrusions |", "|---|---|---:|---|---|---|---:|---|---|"]
    for r in mine:
        c = r.get("controller_outcome") or {}
        refused = ", ".join(f"{k} {v}" for k, v in sorted((c.get("rejections") or {}).items())) or "—"
        intrusions = "; ".join(f"{k}: " + ", ".join(f"{a} {b}" for a, b in v.items())
                               for k, v in (c.get("intrusions") or {}).items()) or "—"
        run = (f"{r['scenario']}{' [secure]' if r['family'].startswith('secure:') else ''} "
               + (" ".join(f"`{f}`" for f in r["faults"]) or "—"))
        lines.append(f"| {run} | {r['outcome']} | {_fmt(r['min_margin'])} | {c.get('start') or '—'} | "
                     f"{c.get('mode') or '—'} | {'yes' if c.get('arming_refused') else 'no'} | "
                     f"{c.get('foreign_commands') or 0} | {refused} | {intrusions} |")
    return lines


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _heatmap(rows, path: Path) -> Path | None:
    cells = grid_cells(rows)
    if len(cells) < 2:
        return None
    import numpy as np
    plt = _plt()
    delays = sorted({d for d, _ in cells})
    losses = sorted({loss for _, loss in cells})
    grid = np.full((len(losses), len(delays)), np.nan)
    for (d, loss), m in cells.items():
        grid[losses.index(loss), delays.index(d)] = m
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    im = ax.imshow(grid, origin="lower", aspect="auto", cmap="RdYlGn", vmin=min(-0.05, np.nanmin(grid)),
                   vmax=max(0.1, np.nanmax(grid)))
    for i in range(len(losses)):
        for j in range(len(delays)):
            if np.isfinite(grid[i, j]):
                ax.text(j, i, f"{grid[i, j] * 100:.1f}", ha="center", va="center", fontsize=8)
    ax.set_xticks(range(len(delays)), [f"{d:g}" for d in delays])
    ax.set_yticks(range(len(losses)), [f"{loss * 100:g} %" for loss in losses])
    ax.set_xlabel("operator → controller delay (ms)")
    ax.set_ylabel("operator → controller loss")
    ax.set_title("adversarial wall: min ground-truth margin (cm)")
    fig.colorbar(im, ax=ax, label="min margin (m)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _family_group(family: str) -> str:
    head = family.split("+")[0]
    return family if len(family) <= 28 else head + "+…"


def _by_family(rows, path: Path) -> Path | None:
    usable = [r for r in rows if r["min_margin"] is not None and r["outcome"] not in ("error", "not exercised")]
    if not usable:
        return None
    plt = _plt()
    fams = sorted({_family_group(r["family"]) for r in usable})
    fig, ax = plt.subplots(figsize=(10, max(4.0, 0.28 * len(fams) + 1.5)))
    for r in usable:
        y = fams.index(_family_group(r["family"]))
        color = "tab:red" if r["violations"] else ("tab:orange" if r["estops"] else "tab:green")
        ax.plot(max(r["min_margin"], -0.5), y, "o", color=color, alpha=0.7, markersize=5)
    ax.axvline(0.0, color="k", lw=1)
    ax.axvline(0.025, color="grey", lw=0.8, ls=":", label="b0 = 0.025 m")
    ax.set_yticks(range(len(fams)), fams, fontsize=8)
    ax.set_xlabel("min ground-truth margin (m; clipped at −0.5)   green: safe, orange: estop, red: violation")
    ax.set_title("min margin per fault family")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _actuation(rows, path: Path) -> Path | None:
    pts = [r for r in rows if r.get("forecast") and r["min_margin"] is not None
           and r["outcome"] not in ("error", "not exercised")]
    if not pts:
        return None
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for r in pts:
        fc = r["forecast"]
        color = "tab:red" if r["violations"] else "tab:green"
        ax.plot(fc["approach_speed"], max(r["min_margin"], -1.5), "o", color=color, alpha=0.8)
        ax.plot(fc["approach_speed"], max(fc["min_margin"], -1.5), "x", color="k", alpha=0.6)
    ax.axhline(0.0, color="k", lw=1)
    ax.set_xlabel("speed toward the nearest face when actuation was lost (m/s, ground truth)")
    ax.set_ylabel("min margin (m; clipped at −1.5)")
    ax.set_title("controller kill / hang, CAN bus-off, estop: measured (o) vs forecast (x)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _stopping(path: Path) -> Path:
    """D(v) of docs/safety.md §2 for the default robot, with the bands b0, b1, b2."""
    import numpy as np

    from sharedctl.models import OmniRobot

    from sharedctl.services.robot.plant import Plant, RobotSimConfig
    from .stopping import worst_coast_model
    plt = _plt()
    plant = Plant(OmniRobot(), RobotSimConfig())
    model = worst_coast_model(plant)
    push = 20.0 / float(plant.model.theta[0])
    v = np.linspace(0.0, 1.5, 151)
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    ax.plot(v, [model.stopping_distance(x) for x in v], label="D(v): last torque 0, watchdog 0.1 s, then braking")
    ax.plot(v, [model.stopping_distance(x, 0.1, push) for x in v], label="D(v): operator's 20 N push held 0.1 s")
    unbraked = worst_coast_model(Plant(OmniRobot(), RobotSimConfig(brake_torque=0.0)))
    ax.plot(v, [unbraked.stopping_distance(x) for x in v], ls="--", color="grey",
            label="D(v) without brakes (wheel friction only)")
    for d, name in ((0.025, "b0"), (0.3, "b1"), (0.6, "b2")):
        ax.axhline(d, color="grey", lw=0.8, ls=":")
        ax.text(0.01, d, f" {name} = {d:g} m", va="bottom", fontsize=8, color="grey")
    ax.set_xlabel("speed toward the face when the drives stop driving (m/s)")
    ax.set_ylabel("distance to rest (m)")
    ax.set_title("stopping distance of the disarmed robot (fail-safe brakes)")
    ax.set_ylim(0.0, 1.0)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
