"""The price of the fail-safe stop: `shared` against `shared-nobackup`, run by run (JSON and report section).

`shared` keeps the robot in backup-safe states (sharedctl/backup.py, docs/safety.md §5);
`shared-nobackup` is the same law with the scenario's `[backup] enabled = false`, on the same
scenario, operator, link and loss seed. Pairing the two rows of one scenario and condition gives
what keeping the stop inside Q_a costs the operator: `backup_price` builds the JSON's entries from
the comparison's rows, `price_section` renders them as Markdown from the JSON document alone.
"""
from __future__ import annotations

PRICE_METRICS = ("human_authority", "tracking_error", "time_to_goal", "min_margin", "violations", "interventions")
WITH, WITHOUT = "shared", "shared-nobackup"


def backup_price(outcomes) -> list[dict]:
    """One entry per scenario and condition run by both variants: `without` and `with` hold their metrics;
    `backup_model` says whether the scenario has a brake model at all (without one the two are the same law)."""
    rows = {(o.row["strategy"], o.row["scenario"]): o for o in outcomes}
    entries = []
    for (strategy, label), with_ in rows.items():
        without = rows.get((WITHOUT, label))
        if strategy != WITH or without is None:
            continue
        entries.append({
            "scenario": label, "base_scenario": with_.row["base_scenario"], "condition": with_.row["condition"],
            "backup_model": with_.loop.backup is not None,
            "without": {k: without.row[k] for k in PRICE_METRICS},
            "with": {k: with_.row[k] for k in PRICE_METRICS},
        })
    return entries


def _pair(entry: dict, key: str, cell) -> str:
    return f"{cell(entry['without'][key])} → {cell(entry['with'][key])}"


def _share(x) -> str:
    return "—" if x is None else f"{x:.3f}"


def _metres(x) -> str:
    return "—" if x is None else f"{x:.3f}"


def _seconds(x) -> str:
    return "—" if x is None else f"{x:.2f}"


def _millimetres(x) -> str:
    return "—" if x is None else f"{x * 1e3:.1f}"


def _count(x) -> str:
    return str(x)


COLUMNS = (  # (heading, metric, cell)
    ("human authority", "human_authority", _share),
    ("tracking RMSE (m)", "tracking_error", _metres),
    ("time to goal (s)", "time_to_goal", _seconds),
    ("min margin (mm)", "min_margin", _millimetres),
    ("violations", "violations", _count),
    ("interventions", "interventions", _count),
)


def price_table(doc: dict) -> list[str]:
    """The table, one line per scenario and condition, each cell `without → with`."""
    lines = ["| scenario | link | " + " | ".join(h for h, _, _ in COLUMNS) + " |",
             "|---|---|" + "---|" * len(COLUMNS)]
    for e in doc.get("backup_price") or []:
        lines.append(f"| {e['base_scenario']} | {e['condition']} | "
                     + " | ".join(_pair(e, key, cell) for _, key, cell in COLUMNS) + " |")
    return lines


def price_section(doc: dict) -> list[str]:
    """The report's section: what is compared, the table, and statements computed from its entries."""
    entries = doc.get("backup_price") or []
    if not entries:
        return []
    tolerance = doc["goal_tolerance"]
    out = ["", "## The price of the fail-safe stop", "",
           f"`{WITH}` keeps the robot in backup-safe states (docs/safety.md §5: speed-aware sets and the governor, "
           "with the scenario's `[backup]` assumptions); "
           f"`{WITHOUT}` runs the same law on the same scenario, operator, link and seed with `[backup] "
           "enabled = false` — the paper's loop. Each cell reads *without → with* the backup-safe sets. "
           f"*Time to goal*: the first instant from which |q − Π(q_d)| ≤ {tolerance:g} (m, rad) holds to the "
           "end of the run (— : farther than that at the end).", ""]
    out += price_table(doc)
    out += [""] + _statements(entries)
    return out


def _statements(entries: list[dict]) -> list[str]:
    n = len(entries)
    lines = []
    plain = [e["scenario"] for e in entries if not e["backup_model"]]
    if plain:
        lines.append(f"- No brake model (the same law twice): {', '.join(f'`{s}`' for s in plain)}.")
    delta = [(e["with"]["human_authority"] - e["without"]["human_authority"], e["scenario"]) for e in entries
             if e["with"]["human_authority"] is not None and e["without"]["human_authority"] is not None]
    less = [d for d in delta if d[0] < 0]
    if less:
        lo, (most, where) = min(-d for d, _ in less), min(less)
        lines.append(f"- **Human authority** is lower with the backup-safe sets in {len(less)} of {n} runs, by "
                     f"{lo:.1%}–{-most:.1%} of the run (most on `{where}`): the speed-aware sets hand the "
                     "machine authority earlier on a fast approach.")
    more = [s for d, s in delta if d > 0]
    if more:
        lines.append(f"- Human authority is higher with them in {', '.join(f'`{s}`' for s in more)}.")
    lines += _changes(entries, "tracking_error", "Tracking RMSE", lambda x: f"{x * 1e3:.1f} mm")
    later = [e for e in entries if _later(e)]
    earlier = [e for e in entries if _later(e) is False]
    never = [e["scenario"] for e in entries
             if e["with"]["time_to_goal"] is None and e["without"]["time_to_goal"] is None]
    goal = []
    if later:
        goal.append("later in " + ", ".join(f"`{e['scenario']}` ({_seconds(e['without']['time_to_goal'])} → "
                                            f"{_seconds(e['with']['time_to_goal'])} s)" for e in later))
    if earlier:
        goal.append("earlier in " + ", ".join(f"`{e['scenario']}` ({_seconds(e['without']['time_to_goal'])} → "
                                              f"{_seconds(e['with']['time_to_goal'])} s)" for e in earlier))
    same = n - len(later) - len(earlier) - len(never)
    if same:
        goal.append(f"at the same instant in {same}")
    if never:
        goal.append("not within the tolerance at the end with or without in " + ", ".join(f"`{s}`" for s in never))
    if goal:
        lines.append("- **Time to goal** with the backup-safe sets: " + "; ".join(goal) + ".")
    wider = [e for e in entries if _gt(e["with"]["min_margin"], e["without"]["min_margin"])]
    if wider:
        lines.append(f"- **The smallest margin** is larger with them in {len(wider)} of {n} runs "
                     f"({_span(wider, 'without')} mm → {_span(wider, 'with')} mm): the stop from the held "
                     "command, not the band alone, decides where the machine takes over.")
    left = [(e["scenario"], v) for e in entries for v in ("without", "with") if e[v]["violations"]]
    if left:
        lines.append("- **Left the set**: " + ", ".join(f"`{s}` {v}" for s, v in left) + ".")
    else:
        lines.append(f"- Neither variant left the set in any of the {n} runs.")
    return lines


def _changes(entries, key, name, unit) -> list[str]:
    pairs = [(e["with"][key] - e["without"][key], e["scenario"]) for e in entries
             if e["with"][key] is not None and e["without"][key] is not None]
    up = [p for p in pairs if p[0] > 0]
    down = [p for p in pairs if p[0] < 0]
    parts = []
    if up:
        d, where = max(up)
        parts.append(f"higher with the backup-safe sets in {len(up)} of {len(entries)} runs (at most by {unit(d)}, "
                     f"`{where}`)")
    if down:
        d, where = min(down)
        parts.append(f"lower in {len(down)} (at most by {unit(-d)}, `{where}`)")
    if len(pairs) - len(up) - len(down):
        parts.append(f"equal in {len(pairs) - len(up) - len(down)}")
    return [f"- **{name}** is " + "; ".join(parts) + "."] if parts else []


def _later(entry) -> bool | None:
    """True if the goal was reached later with the backup-safe sets (or only without them), False if
    earlier (or only with them), None if at the same instant or in neither run."""
    a, b = entry["without"]["time_to_goal"], entry["with"]["time_to_goal"]
    if a is None and b is None:
        return None
    if b is None:
        return True
    if a is None:
        return False
    return True if b > a else False if b < a else None


def _gt(a, b) -> bool:
    return a is not None and b is not None and a > b


def _span(entries, side) -> str:
    values = [e[side]["min_margin"] * 1e3 for e in entries]
    return f"{min(values):.1f}–{max(values):.1f}" if len(values) > 1 else f"{values[0]:.1f}"
