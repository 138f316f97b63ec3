"""Figures of closed-loop runs: the path in the feasible set, and the signals over time.

* `run_figure` — one run on one page (`sharedctl sim --plot`): the path in the shaded set,
  q(t), the inputs, authority, θ̂(t) and the margin.
* `paper_figures` — the set of Section 5 of Tang & Sun (2025): per scenario, the three
  controllers' paths in the shaded feasible set (Figures 1 and 5) and one "system response"
  page per controller (Figures 2–4 and 6–8). Each run carries the description of the law it
  ran (the paper command's laws.describe); titles, legends and captions print it as given.

The feasible set is drawn in the plane of the first two coordinates (x–y for the omni robot,
q1–q2 for the arm), sliced at the other coordinates = 0. Figures are built on
`matplotlib.figure.Figure` directly (Agg backend, no pyplot state): save, then drop.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator, Sequence

import textwrap

import matplotlib

matplotlib.use("Agg")

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

AUTHORITY = {0: ("human", "#1f77b4"), 1: ("shared", "#ff7f0e"), 2: ("machine", "#d62728")}
SET_CLASS = {0: ("safe", "#b7e1a1"), 1: ("hysteresis", "#fdd49e"), 2: ("hazard", "#f4606c")}
LAW_ROLE = {0: ("tracking role", "#9467bd"), 1: ("hazard role", "#8c2d04")}   # while engaged (MachineController)
CONTROLLER_COLOURS = {"ce": "#1f77b4", "nce": "#2ca02c", "of": "#9467bd"}
FEASIBLE_FILL, OBSTACLE_FILL = "#e3f2dc", "#e6e6e6"
PARAMETER_UNITS = {"m1": "kg", "m3": "kg·m²", "a": "kg"}  # the omni robot's θ (Section 5)
FONT = {"font.size": 10, "axes.titlesize": 11, "axes.labelsize": 10, "legend.fontsize": 8.5}


@dataclass(frozen=True)
class Run:
    """One simulated run, as the paper figures need it."""

    scenario: str      # short label, e.g. "convex"
    controller: str    # "ce" | "nce" | "of"
    trace: object      # sharedctl.simulator.Trace
    loop: object       # sharedctl.simulator.ClosedLoop
    law: str           # what the configuration ran, e.g. "(46) with (12)"


@dataclass(frozen=True)
class PaperFigure:
    filename: str
    caption: str
    figure: Figure


# ---------------------------------------------------------------- units and labels

def _units(model) -> list[str]:
    """Per coordinate: m for a position (x, y, z), rad for an angle."""
    return ["m" if name in ("x", "y", "z") else "rad" for name in model.coordinate_names]


def _input_units(model) -> list[str]:
    return ["N" if unit == "m" else "N·m" for unit in _units(model)]


def _label(symbol: str, units: Sequence[str]) -> str:
    return f"{symbol} ({', '.join(dict.fromkeys(units))})"


def _coordinate_labels(model) -> list[str]:
    return [name.replace("psi", "ψ") for name in model.coordinate_names]


def _math(name: str) -> str:
    """A coordinate name as mathtext: psi → \\psi, q1 → q_1."""
    name = name.replace("psi", r"\psi")
    stem = name.rstrip("0123456789")
    return stem + (f"_{{{name[len(stem):]}}}" if stem != name else "")


def _colour(i: int) -> str:
    return f"C{i % 10}"


# ---------------------------------------------------------------- the feasible set in the plane

def feasible_mask(feasible, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """True where (x, y, 0, …) lies in the union of the regions {q : K q + T < 0}."""
    Q = np.zeros((feasible.n, X.size))
    Q[0], Q[1] = X.ravel(), Y.ravel()
    inside = np.zeros(X.size, dtype=bool)
    for region in feasible.regions:
        inside |= np.all(region.K @ Q + region.T[:, None] < 0.0, axis=0)
    return inside.reshape(X.shape)


def _vertices(feasible) -> np.ndarray:
    """Corners of each region's slice in the plane (pairs of faces that meet inside the region)."""
    points = []
    for region in feasible.regions:
        K2, T = region.K[:, :2], region.T
        rows = [j for j in range(len(T)) if np.linalg.norm(K2[j]) > 1e-9]
        for a in rows:
            for b in rows:
                if b <= a or abs(np.linalg.det(K2[[a, b]])) < 1e-9:
                    continue
                p = np.linalg.solve(K2[[a, b]], -T[[a, b]])
                if np.all(K2 @ p + T <= 1e-9):
                    points.append(p)
    return np.array(points).reshape(-1, 2)


def plane_limits(traces, feasible) -> tuple[tuple[float, float], tuple[float, float]]:
    """Limits covering the paths and references, q_d clipped if it runs far off, nearby corners."""
    path = np.vstack([np.vstack([tr.q[:, :2], tr.q_r[:, :2]]) for tr in traces])
    path = path[np.all(np.isfinite(path), axis=1)]
    lo, hi = path.min(axis=0), path.max(axis=0)
    span = np.maximum(hi - lo, 0.5).max()
    desired = np.vstack([tr.q_d[:, :2] for tr in traces])
    desired = np.clip(desired[np.all(np.isfinite(desired), axis=1)], lo - 0.6 * span, hi + 0.6 * span)
    pts = np.vstack([path, desired])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    corners = _vertices(feasible)
    near = np.all((corners >= lo - 0.25 * span) & (corners <= hi + 0.25 * span), axis=1)
    pts = np.vstack([pts, corners[near]])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    width = np.maximum(hi - lo, 0.75 * (hi - lo).max())   # no sliver of a plot
    centre = (lo + hi) / 2
    half = 0.5 * width * 1.16
    return (centre[0] - half[0], centre[0] + half[0]), (centre[1] - half[1], centre[1] + half[1])


def draw_feasible_set(ax, feasible, xlim, ylim, resolution: int = 500) -> list:
    """Shade the set and its complement, outline the union, draw each polytope's faces."""
    wx, wy = xlim[1] - xlim[0], ylim[1] - ylim[0]
    xs = np.linspace(xlim[0] - 0.02 * wx, xlim[1] + 0.02 * wx, resolution)
    ys = np.linspace(ylim[0] - 0.02 * wy, ylim[1] + 0.02 * wy, resolution)
    X, Y = np.meshgrid(xs, ys)
    mask = feasible_mask(feasible, X, Y).astype(float)
    ax.contourf(X, Y, mask, levels=[-0.5, 0.5, 1.5], colors=[OBSTACLE_FILL, FEASIBLE_FILL])
    ax.contourf(X, Y, mask, levels=[-0.5, 0.5], colors="none", hatches=["///"])
    ax.contour(X, Y, mask, levels=[0.5], colors="k", linewidths=1.6)
    s = np.linspace(-1.0, 1.0, 2000) * 2 * max(wx, wy)
    centre = np.array([(xlim[0] + xlim[1]) / 2, (ylim[0] + ylim[1]) / 2])
    for region in feasible.regions:
        K2, T = region.K[:, :2], region.T
        for j in range(len(T)):
            normal = K2[j]
            if np.linalg.norm(normal) < 1e-9:
                continue
            foot = centre - (normal @ centre + T[j]) / (normal @ normal) * normal
            line = foot[None, :] + s[:, None] * np.array([-normal[1], normal[0]]) / np.linalg.norm(normal)
            others = np.delete(np.arange(len(T)), j)
            on_face = np.all(K2[others] @ line.T + T[others][:, None] <= 1e-9, axis=0)
            line[~on_face] = np.nan
            ax.plot(line[:, 0], line[:, 1], color="0.35", lw=0.9, ls=(0, (4, 3)), zorder=1)
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    return [
        Patch(facecolor=FEASIBLE_FILL, edgecolor="k", label="feasible set $Q_a$"),
        Patch(facecolor=OBSTACLE_FILL, edgecolor="0.4", hatch="///", label="outside $Q_a$"),
        Line2D([], [], color="0.35", lw=0.9, ls=(0, (4, 3)), label="polytope faces"),
    ]


def draw_direction_arrows(ax, xy: np.ndarray, colour: str, count: int = 7, size: float = 16) -> None:
    """Arrow heads along a path, evenly spaced in arc length, pointing the way it was travelled."""
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    if len(xy) < 3:
        return
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    if arc[-1] < 1e-9:
        return
    step = 0.015 * arc[-1]
    for target in np.linspace(0.0, arc[-1], count + 2)[1:-1]:
        i = min(int(np.searchsorted(arc, target)), len(xy) - 2)
        j = min(int(np.searchsorted(arc, arc[i] + step)), len(xy) - 1)
        if j > i:
            ax.annotate("", xy=xy[j], xytext=xy[i], zorder=5,
                        arrowprops=dict(arrowstyle="-|>", color=colour, lw=1.4, mutation_scale=size))


def draw_path_by_authority(ax, trace, lw: float = 2.0, small: bool = False) -> list:
    """The path coloured by who had authority; machine-only samples also marked."""
    xy = trace.q[:, :2]
    segments = np.stack([xy[:-1], xy[1:]], axis=1)
    colours = [AUTHORITY[int(a)][1] for a in trace.authority[:-1]]
    ax.add_collection(LineCollection(segments, colors=colours, linewidths=lw, zorder=4))
    machine = trace.authority == 2
    if machine.any():
        ax.plot(xy[machine, 0], xy[machine, 1], "o" if small else "x", color=AUTHORITY[2][1], mfc="none",
                ms=5 if small else 7, mew=0.9 if small else 1.8, zorder=6)
    draw_direction_arrows(ax, xy, "k", count=5 if small else 7, size=11 if small else 16)
    return [Line2D([], [], color=AUTHORITY[a][1], lw=lw, label=f"q, {AUTHORITY[a][0]} authority") for a in (0, 1)] + [
        Line2D([], [], color=AUTHORITY[2][1], marker="o" if small else "x", mfc="none", ms=7, ls="none",
               mew=1.5, label="q, machine authority")
    ]


def _start_end(ax, trace, colour="k") -> list:
    finite = trace.q[np.all(np.isfinite(trace.q), axis=1)]
    ax.plot(*finite[0, :2], "o", color=colour, mfc="white", ms=9, mew=2, zorder=7)
    ax.plot(*finite[-1, :2], "s", color=colour, ms=8, zorder=7)
    return [Line2D([], [], marker="o", color="k", mfc="white", ls="none", mew=2, label="start"),
            Line2D([], [], marker="s", color="k", ls="none", label="end")]


def _plane_axes(ax, loop, title: str) -> None:
    names = _coordinate_labels(loop.model)
    units = _units(loop.model)
    ax.set_xlabel(f"{names[0]} ({units[0]})")
    ax.set_ylabel(f"{names[1]} ({units[1]})")
    ax.set_aspect("equal", adjustable="box")
    ax.set_title(title)


def trajectory_panel(ax, trace, loop, title: str = "Path in the feasible set") -> None:
    """Panel (a): shaded set, q by authority with arrows, q_d dashed, q_r dotted, start/end."""
    xlim, ylim = plane_limits([trace], loop.feasible)
    handles = draw_feasible_set(ax, loop.feasible, xlim, ylim)
    ax.plot(trace.q_d[:, 0], trace.q_d[:, 1], "--", color="k", lw=1.3, zorder=3)
    ax.plot(trace.q_r[:, 0], trace.q_r[:, 1], ":", color="#8c564b", lw=1.8, zorder=3)
    handles += draw_path_by_authority(ax, trace)
    handles += [Line2D([], [], color="k", ls="--", label="$q_d$ (operator's desired)"),
                Line2D([], [], color="#8c564b", ls=":", lw=1.8, label="$q_r$ (projected reference)")]
    handles += _start_end(ax, trace)
    _plane_axes(ax, loop, title)
    ax.legend(handles=handles, loc="best", framealpha=0.9, fontsize=8)


# ---------------------------------------------------------------- signals over time

def states_panel(ax, trace, loop) -> None:
    """q(t) solid, q_d(t) dashed, q_r(t) dotted; one colour per coordinate."""
    for i, name in enumerate(_coordinate_labels(loop.model)):
        ax.plot(trace.t, trace.q[:, i], color=_colour(i), lw=1.6, label=name)
        ax.plot(trace.t, trace.q_d[:, i], "--", color=_colour(i), lw=1.0)
        ax.plot(trace.t, trace.q_r[:, i], ":", color=_colour(i), lw=1.6)
    handles, _ = ax.get_legend_handles_labels()
    handles += [Line2D([], [], color="0.3", ls="--", label="$q_d$"), Line2D([], [], color="0.3", ls=":", label="$q_r$")]
    _legend(ax, handles)
    ax.set_ylabel(_label("q", _units(loop.model)))
    ax.set_title("States q(t), desired $q_d$, projected reference $q_r$")


def velocities_panel(ax, trace, loop) -> None:
    estimated = not np.allclose(trace.v, trace.v_hat, equal_nan=True)
    for i, name in enumerate(loop.model.coordinate_names):
        ax.plot(trace.t, trace.v[:, i], color=_colour(i), lw=1.4, label=f"$\\dot{{{_math(name)}}}$")
        if estimated:
            ax.plot(trace.t, trace.v_hat[:, i], ":", color=_colour(i), lw=1.4)
    handles, _ = ax.get_legend_handles_labels()
    if estimated:
        handles.append(Line2D([], [], color="0.3", ls=":", label="observer $\\hat{\\dot q}$"))
    _legend(ax, handles)
    ax.set_ylabel(_label("$\\dot{q}$", [u + "/s" for u in _units(loop.model)]))
    ax.set_title("Velocities" + (" (true, and the observer's estimate)" if estimated else ""))


def _clip_to_bulk(ax, values: np.ndarray, unit_label: str, what: str) -> None:
    """Scale to the bulk of the signal; say so when short peaks go off the axes."""
    finite = np.abs(values[np.isfinite(values)])
    if finite.size == 0:
        return
    peak, bulk = float(finite.max()), float(np.percentile(finite, 99.5))
    limit = max(1.25 * bulk, 1.0)
    if peak > limit:
        ax.set_ylim(-limit, limit)
        ax.text(0.01, 0.04, f"peaks clipped: max |{what}| = {peak:.0f} {unit_label}", transform=ax.transAxes,
                fontsize=8, color="0.25", bbox=dict(facecolor="white", alpha=0.8, lw=0))


SIGNALS = {"u_h": ("$u_h$ operator", "--"), "u_f": ("$u_f$ machine", ":"), "u_s": ("$u_s$ applied", "-")}


def inputs_panel(ax, trace, loop, signals: Sequence[str] = ("u_h", "u_f", "u_s")) -> None:
    """Inputs over time; colour per coordinate, line style per signal when several are drawn."""
    names, units = _coordinate_labels(loop.model), _input_units(loop.model)
    for key in signals:
        data = getattr(trace, key)
        style = SIGNALS[key][1] if len(signals) > 1 else "-"
        for i in range(data.shape[1]):
            ax.plot(trace.t, data[:, i], style, color=_colour(i), lw=1.0 if key != "u_s" else 1.3)
    handles = [Line2D([], [], color=_colour(i), label=f"{n} ({u})") for i, (n, u) in enumerate(zip(names, units))]
    if len(signals) > 1:
        handles += [Line2D([], [], color="0.3", ls=SIGNALS[k][1], label=SIGNALS[k][0]) for k in signals]
    _legend(ax, handles)
    ax.set_ylabel(_label("u", units))
    ax.set_title("Inputs " + ", ".join(SIGNALS[k][0] for k in signals))
    _clip_to_bulk(ax, np.concatenate([getattr(trace, k).ravel() for k in signals]), units[0], "/".join(signals))


def torques_panel(ax, trace, loop) -> None:
    for i in range(trace.tau.shape[1]):
        ax.plot(trace.t, trace.tau[:, i], color=_colour(i + 3), lw=1.0, label=f"wheel {i + 1}")
    _legend(ax)
    ax.set_ylabel("τ (N·m)")
    ax.set_title("Wheel torques $\\tau_s = B(\\psi)^{-1} u_s$")
    _clip_to_bulk(ax, trace.tau.ravel(), "N·m", "τ")


def _runs(values: np.ndarray) -> list[tuple[int, int, int]]:
    """(start, end, value) of each constant stretch."""
    edges = np.flatnonzero(values[1:] != values[:-1]) + 1
    starts, ends = np.r_[0, edges], np.r_[edges, len(values)]
    return [(int(s), int(e), int(values[s])) for s, e in zip(starts, ends)]


def _band(ax, t: np.ndarray, values: np.ndarray, palette: dict, y0: float, height: float) -> None:
    dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
    for value, (_, colour) in palette.items():
        spans = [(t[s], (e - s) * dt) for s, e, v in _runs(values) if v == value]
        if spans:  # an edge in the face colour keeps one-sample stretches visible
            ax.broken_barh(spans, (y0, height), facecolors=colour, edgecolors=colour, linewidth=0.6)


def machine_law_role(trace) -> np.ndarray:
    """The law role while the machine is engaged (0 tracking, 1 hazard), −1 under human authority."""
    return np.where(trace.authority != 0, trace.role, -1)


def authority_panel(ax, trace, loop=None) -> None:
    """k_h, k_f in [0, 1]; above them three bands: set class, k_s (who had authority), law run."""
    _band(ax, trace.t, trace.set_class, SET_CLASS, 1.08, 0.14)
    _band(ax, trace.t, trace.authority, AUTHORITY, 1.28, 0.14)
    _band(ax, trace.t, machine_law_role(trace), LAW_ROLE, 1.48, 0.14)
    ax.plot(trace.t, trace.k_h, color="#17becf", lw=1.3, label="$k_h$ (operator weight)")
    ax.plot(trace.t, trace.k_f, color="#7f7f7f", lw=1.3, ls="--", label="$k_f$ (machine weight)")
    ax.set_ylim(-0.05, 1.67)
    ax.set_yticks([0, 0.5, 1.0, 1.15, 1.35, 1.55], ["0", "0.5", "1", "set", "$k_s$", "law"])
    handles, _ = ax.get_legend_handles_labels()
    handles += [Patch(color=c, label=f"set: {n}") for n, c in SET_CLASS.values()]
    handles += [Patch(color=c, label=f"authority: {n}") for n, c in AUTHORITY.values()]
    handles += [Patch(color=c, label=f"law: {n}") for n, c in LAW_ROLE.values()]
    if loop is not None and loop.controller.hazard is not loop.controller.tracking:
        handles[-1] = Patch(color=LAW_ROLE[1][1], label=f"law: hazard role, the {loop.controller.hazard.name} law")
    _legend(ax, handles, fontsize=7.5)
    switches = int(trace.switches)
    ax.set_title(f"Authority: set class, $k_s$, machine law, weights ({switches} switches)")
    ax.set_ylabel("weight")


def estimates_panel(ax, trace, loop) -> None:
    """θ̂(t) solid, the true θ dashed in the same colour."""
    theta = np.asarray(loop.model.theta, dtype=float)
    for i, name in enumerate(loop.model.parameter_names):
        unit = PARAMETER_UNITS.get(name)
        ax.plot(trace.t, trace.theta_hat[:, i], color=_colour(i), lw=1.5, label=name + (f" ({unit})" if unit else ""))
        ax.axhline(theta[i], color=_colour(i), ls="--", lw=1.0)
    handles, _ = ax.get_legend_handles_labels()
    handles.append(Line2D([], [], color="0.3", ls="--", label="true θ"))
    _legend(ax, handles)
    ax.set_ylabel("θ̂, θ")
    ax.set_title("Parameter estimates θ̂(t) from θ̂(0) = 0; true θ dashed")


def margin_panel(ax, trace, loop) -> None:
    """The best region's smallest slack; zero is the border."""
    ax.plot(trace.t, trace.margin, color="k", lw=1.3, label="margin")
    ax.axhline(0.0, color="#d62728", lw=1.2, label="border (0)")
    bands = loop.sharing.bands
    for b, ls in ((bands.b1, ":"), (bands.b2, "-.")):
        ax.axhline(b, color="0.45", lw=0.9, ls=ls, label=f"band $b_{1 if b == bands.b1 else 2}$ = {b:g}")
    k = int(np.nanargmin(trace.margin)) if np.isfinite(trace.margin).any() else 0
    ax.plot(trace.t[k], trace.margin[k], "v", color="#d62728", ms=8,
            label=f"min {trace.margin[k]:.3g} at t = {trace.t[k]:.2f} s")
    _legend(ax)
    units = sorted(set(_units(loop.model)))
    ax.set_ylabel(f"margin ({', '.join(units)})")
    ax.set_title("Margin to the border (best region's slack)")


def _legend(ax, handles=None, **kwargs) -> None:
    """Legends of time panels sit to the right of the axes, off the data."""
    if handles is None:
        handles, _ = ax.get_legend_handles_labels()
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.005, 1.0), borderaxespad=0.0,
              framealpha=0.9, **kwargs)


def time_axis(ax) -> None:
    """The time axis of a signal panel: label and grid."""
    ax.set_xlabel("t (s)")
    ax.grid(True, alpha=0.3)


# ---------------------------------------------------------------- pages

def run_figure(trace, loop, title: str) -> Figure:
    """One run: (a) path in the set, (b) q(t), (c) inputs, (d) authority, (e) θ̂(t), (f) margin."""
    with matplotlib.rc_context(FONT):
        fig = Figure(figsize=(15, 10), layout="constrained")
        outer = fig.add_gridspec(1, 2, width_ratios=[1.0, 1.45])
        left = outer[0].subgridspec(2, 1, height_ratios=[2.2, 1])
        right = outer[1].subgridspec(4, 1)
        trajectory_panel(fig.add_subplot(left[0]), trace, loop, "(a) Path in the feasible set")
        margin_panel(ax := fig.add_subplot(left[1]), trace, loop)
        ax.set_title("(f) " + ax.get_title())
        time_axis(ax)
        first = None
        for k, (panel, tag) in enumerate(((states_panel, "b"), (inputs_panel, "c"),
                                          (authority_panel, "d"), (estimates_panel, "e"))):
            ax = fig.add_subplot(right[k], sharex=first)
            first = first or ax
            panel(ax, trace, loop)
            ax.set_title(f"({tag}) " + ax.get_title())
            time_axis(ax)
        fig.suptitle(title, fontsize=14, fontweight="bold")
    return fig


def response_figure(trace, loop, title: str) -> Figure:
    """The paper's "system response" page (Figures 2–4, 6–8): states, inputs, authority, θ̂."""
    with matplotlib.rc_context(FONT):
        fig = Figure(figsize=(15, 13), layout="constrained")
        grid = fig.add_gridspec(4, 2)
        panels = [
            (states_panel, {}), (velocities_panel, {}),
            (inputs_panel, {"signals": ("u_h",)}), (inputs_panel, {"signals": ("u_f",)}),
            (inputs_panel, {"signals": ("u_s",)}),
            (torques_panel if hasattr(loop.model, "wheel_torques") else margin_panel, {}),
            (authority_panel, {}), (estimates_panel, {}),
        ]
        first = None
        for k, (panel, kwargs) in enumerate(panels):
            ax = fig.add_subplot(grid[k // 2, k % 2], sharex=first)
            first = first or ax
            panel(ax, trace, loop, **kwargs)
            ax.set_title(f"({'abcdefgh'[k]}) " + ax.get_title())
            time_axis(ax)
        fig.suptitle(title, fontsize=14, fontweight="bold")
    return fig


def comparison_figure(runs: Sequence[Run], title: str) -> Figure:
    """Figures 1 / 5: all controllers' paths in the shaded set (left); each run by authority (right)."""
    loop = runs[0].loop
    with matplotlib.rc_context(FONT):
        fig = Figure(figsize=(15, 10), layout="constrained")
        outer = fig.add_gridspec(1, 2, width_ratios=[1.25, 1])
        right = outer[1].subgridspec(2, 2)
        ax = fig.add_subplot(outer[0])
        xlim, ylim = plane_limits([r.trace for r in runs], loop.feasible)
        handles = draw_feasible_set(ax, loop.feasible, xlim, ylim)
        ax.plot(runs[0].trace.q_d[:, 0], runs[0].trace.q_d[:, 1], "--", color="k", lw=1.4, zorder=3)
        handles.append(Line2D([], [], color="k", ls="--", label="$q_d$ (operator's desired)"))
        for r in runs:
            colour = CONTROLLER_COLOURS[r.controller]
            ax.plot(r.trace.q[:, 0], r.trace.q[:, 1], color=colour, lw=2.0, zorder=4, alpha=0.85)
            draw_direction_arrows(ax, r.trace.q[:, :2], colour, count=6, size=18)
            handles.append(Line2D([], [], color=colour, lw=2,
                                  label=textwrap.fill(f"{r.controller}: {r.law}", 44, subsequent_indent="    ")))
        handles += _start_end(ax, runs[0].trace)
        for r in runs:   # each run's own end (a run that diverged stops early)
            end = r.trace.q[np.all(np.isfinite(r.trace.q), axis=1)][-1, :2]
            ax.plot(*end, "s", color=CONTROLLER_COLOURS[r.controller], mec="k", ms=9, zorder=8)
        _plane_axes(ax, loop, "All controllers (arrows: direction of travel)")
        authority = []
        for k, r in enumerate(runs[:3]):
            sub = fig.add_subplot(right[k // 2, k % 2])
            draw_feasible_set(sub, loop.feasible, xlim, ylim, resolution=250)
            sub.plot(r.trace.q_d[:, 0], r.trace.q_d[:, 1], "--", color="k", lw=1.0, zorder=3)
            authority = draw_path_by_authority(sub, r.trace, lw=2.4, small=True)
            _start_end(sub, r.trace)
            _plane_axes(sub, loop, f"{r.controller}: path by authority ({int(r.trace.switches)} switches)")
        key = fig.add_subplot(right[1, 1])
        key.axis("off")
        first = key.legend(handles=handles, loc="upper center", title="All controllers", fontsize=8.5)
        key.add_artist(first)
        key.legend(handles=authority, loc="lower center", title="Per controller: who had authority", fontsize=8.5)
        fig.suptitle(title, fontsize=14, fontweight="bold")
    return fig


PAPER_NUMBERS = {"convex": 1, "nonconvex": 5}   # Figure 1 (+2–4) and Figure 5 (+6–8)
PAPER_SET_NAMES = {"convex": "convex $Q_a$", "nonconvex": "non-convex $Q_a$"}


def paper_figures(runs: Sequence[Run]) -> Iterator[PaperFigure]:
    """Figures 1–8 of Section 5, one at a time (save and drop each before the next is drawn).

    Numbering follows the paper whatever subset of controllers ran: scenario "convex" is
    Figure 1 (paths) and 2/3/4 (ce/nce/of); "nonconvex" is 5 and 6/7/8. Every caption names
    the law of each run it shows (`Run.law`).
    """
    order = list(CONTROLLER_COLOURS)
    scenarios = list(dict.fromkeys(r.scenario for r in runs))
    for s_index, scenario in enumerate(scenarios):
        base = PAPER_NUMBERS.get(scenario, 1 + 4 * (s_index + len(PAPER_NUMBERS)))
        group = sorted((r for r in runs if r.scenario == scenario), key=lambda r: order.index(r.controller))
        where = PAPER_SET_NAMES.get(scenario, scenario)
        title = f"Trajectory tracking under the {where}: {', '.join(r.controller for r in group)}"
        laws = "; ".join(f"{r.controller} — {r.law}" for r in group)
        yield PaperFigure(f"fig{base}_{scenario}_trajectory.png",
                          f"{title}, in the shaded feasible set, arrows along the direction of travel ({laws})"
                          .replace("$", ""),
                          comparison_figure(group, f"Figure {base}. {title}"))
        for r in group:
            number = base + 1 + order.index(r.controller)
            title = f"System response — {r.controller}: {r.law}, under the {where}"
            extra = "wheel torques" if hasattr(r.loop.model, "wheel_torques") else "margin"
            yield PaperFigure(f"fig{number}_{scenario}_{r.controller}.png",
                              title.replace("$", "") + f": q, q̇, u_h, u_f, u_s, {extra}, authority, θ̂",
                              response_figure(r.trace, r.loop, textwrap.fill(f"Figure {number}. {title}", 120)))
