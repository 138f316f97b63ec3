"""Figures of `sharedctl compare`: metric bars, paths in the feasible set, margin and force over time.

Built on `matplotlib.figure.Figure` (Agg backend, no pyplot state), like services/figures.py,
whose feasible-set drawing they reuse.
"""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from sharedctl.services.studies.figures import FONT, draw_feasible_set

COLOURS = {"human": "#7f7f7f", "mux": "#ff7f0e", "cbf": "#2ca02c", "shared": "#1f77b4", "shared-nobackup": "#9467bd"}
METRICS = (  # key, axis label, log scale
    ("violations", "violations (samples outside)", False),
    ("min_margin", "min margin (m)", False),
    ("tracking_error", "tracking error to Π(q_d), RMS", False),
    ("human_authority", "human authority share", False),
    ("interventions", "interventions", False),
    ("control_effort", "control effort ∫|u|² dt (N² s)", True),
    ("jerk_rms", "jerk, RMS (m/s³)", True),
)


def metrics_figure(rows: list[dict], strategies, scenarios) -> Figure:
    """Grouped bars: one group per scenario (and condition), one bar per strategy, one panel per metric."""
    with matplotlib.rc_context(FONT):
        fig = Figure(figsize=(16, 11), layout="constrained")
        axes = fig.subplots(4, 2).ravel()
        width = 0.8 / len(strategies)
        x = np.arange(len(scenarios))
        table = {(r["strategy"], r["scenario"]): r for r in rows}
        for ax, (key, label, log) in zip(axes, METRICS):
            for i, s in enumerate(strategies):
                values = [table[(s, sc)][key] if (s, sc) in table and table[(s, sc)][key] is not None else np.nan
                          for sc in scenarios]
                ax.bar(x + (i - (len(strategies) - 1) / 2) * width, values, width, color=COLOURS.get(s), label=s)
            if key == "min_margin":
                ax.axhline(0.0, color="k", lw=0.8)
                ax.set_ylim(bottom=max(ax.get_ylim()[0], -0.3))
                ax.text(0.01, 0.02, "human bars below −0.3 m are cut", transform=ax.transAxes, fontsize=7.5)
            if log:
                ax.set_yscale("log")
            ax.set_ylabel(label)
            ax.set_xticks(x, [sc.replace("/", "\n") for sc in scenarios], fontsize=7.5, rotation=20, ha="right")
            ax.grid(True, axis="y", alpha=0.3)
        axes[-1].axis("off")
        axes[-1].legend(handles=[Line2D([], [], color=COLOURS.get(s), lw=8, label=s) for s in strategies],
                        loc="center", fontsize=12, title="strategy")
        fig.suptitle("Every strategy on every scenario, ideal link and 100 ms + 20 % loss")
    return fig


def _limits(outcomes):
    pts = [o.trace.q[:, :2] for o in outcomes if o.row["strategy"] != "human"]
    pts += [o.trace.wish[:, :2] for o in outcomes]
    pts = np.vstack(pts)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    lo, hi = pts.min(axis=0) - 0.5, pts.max(axis=0) + 0.5
    centre, half = (lo + hi) / 2, np.max(hi - lo) / 2
    return (centre[0] - half, centre[0] + half), (centre[1] - half, centre[1] + half)


def paths_figure(outcomes, conditions, title: str) -> Figure:
    """One panel per link condition: the feasible set, the wish and every strategy's path (x–y)."""
    with matplotlib.rc_context(FONT):
        fig = Figure(figsize=(13, 6.4), layout="constrained")
        axes = np.atleast_1d(fig.subplots(1, len(conditions)))
        xlim, ylim = _limits(outcomes)
        for ax, condition in zip(axes, conditions):
            runs = [o for o in outcomes if o.condition.name == condition]
            handles = draw_feasible_set(ax, runs[0].loop.feasible, xlim, ylim, resolution=300)
            wish = runs[0].trace.wish
            ax.plot(wish[:, 0], wish[:, 1], "k--", lw=1.2, zorder=3)
            ax.plot(wish[-1, 0], wish[-1, 1], "k*", ms=11, zorder=5)
            handles.append(Line2D([], [], color="k", ls="--", marker="*", label="operator's wish $q_d$"))
            for o in runs:
                s = o.row["strategy"]
                ax.plot(o.trace.q[:, 0], o.trace.q[:, 1], color=COLOURS.get(s), lw=1.8, zorder=4)
                ax.plot(o.trace.q[-1, 0], o.trace.q[-1, 1], "s", color=COLOURS.get(s), ms=6, zorder=6)
                handles.append(Line2D([], [], color=COLOURS.get(s), lw=1.8, marker="s",
                                      label=f"{s} ({o.row['violations']} samples outside)"))
            ax.plot(*runs[0].trace.q[0, :2], "o", color="k", mfc="white", ms=9, mew=2, zorder=7)
            ax.set_xlim(*xlim)
            ax.set_ylim(*ylim)
            ax.set_aspect("equal", adjustable="box")
            ax.set_xlabel("x (m)")
            ax.set_ylabel("y (m)")
            ax.set_title(condition)
            ax.legend(handles=handles, loc="best", fontsize=7.5, framealpha=0.9)
        fig.suptitle(title)
    return fig


def signals_figure(outcomes, title: str) -> Figure:
    """Margin, |u| and who is in control over time, every strategy (one condition)."""
    with matplotlib.rc_context(FONT):
        fig = Figure(figsize=(13, 8.5), layout="constrained")
        ax_m, ax_u, ax_c = fig.subplots(3, 1, sharex=True, height_ratios=[2, 2, 1])
        for i, o in enumerate(outcomes):
            s, tr = o.row["strategy"], o.trace
            c = COLOURS.get(s)
            ax_m.plot(tr.t, tr.margin, color=c, lw=1.3, label=s)
            ax_u.plot(tr.t, np.linalg.norm(tr.u, axis=1), color=c, lw=1.0, label=s)
            y = len(outcomes) - 1 - i
            ax_c.fill_between(tr.t, y + 0.1, y + 0.9, where=~tr.operator_in_control, color=c, step="post", lw=0)
        ax_m.axhline(0.0, color="k", lw=0.8)
        lo = min(float(np.nanmin(o.trace.margin)) for o in outcomes if o.row["strategy"] != "human")
        ax_m.set_ylim(min(lo, 0.0) - 0.05, None)
        ax_m.set_ylabel("margin to the nearest face (m)\n(human cut below)")
        ax_u.set_yscale("symlog", linthresh=10.0)
        ax_u.set_ylim(bottom=0.0)
        ax_u.set_ylabel("|u| (N)")
        ax_c.set_yticks([len(outcomes) - 1 - i + 0.5 for i in range(len(outcomes))],
                        [o.row["strategy"] for o in outcomes])
        ax_c.set_ylim(0, len(outcomes))
        ax_c.set_ylabel("operator overridden")
        ax_c.set_xlabel("t (s)")
        for ax in (ax_m, ax_u):
            ax.grid(True, alpha=0.3)
            ax.legend(loc="upper right", fontsize=8)
        fig.suptitle(title)
    return fig
