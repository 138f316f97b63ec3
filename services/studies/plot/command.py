"""`sharedctl plot FILE.mcap --out DIR [--scenario S]` — the figure set of a recorded run.

Writes PNG files to DIR:

* ``trajectory.png`` — the path in the shaded feasible set, coloured by authority, with the
  operator's wish q_d, the projected reference q_r and (when recorded) the ground truth;
* ``states.png``, ``inputs.png``, ``authority.png``, ``estimates.png`` (θ̂ against the true θ),
  ``margin.png`` — the panels of ``sharedctl sim --plot`` (services/figures.py), over log time;
* ``link.png`` — link health from RobotState (operator latency, loss, staleness, CAN feedback
  age), every topic's message rate, and the events;
* ``overview.png`` — the one-page figure of ``sharedctl sim --plot``.

The feasible set, the model and the true θ come from the scenario stored in the recording's
metadata (``--scenario`` overrides it). Without RobotState in the recording (a recorder that
heard only the simulator) only the trajectory of the ground truth and ``link.png`` are drawn.
A file cut short by a crash is plotted up to its last complete chunk.
"""
from __future__ import annotations

import sys
import tomllib
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from sharedctl.scenario import ScenarioError, parse

from sharedctl.services.studies import figures   # sets the Agg backend; the panels are shared with sharedctl sim --plot
from sharedctl.services.scenario_files import load
from sharedctl.services.recording.recorded_run import LINK_FIELDS, RecordedRun, load_run

PROG = "sharedctl plot"
DPI = 110
LINK_LABELS = {"operator_latency_ms": "operator latency (ms)", "loss_fraction": "operator loss (fraction)",
               "staleness_ms": "operator staleness (ms)", "can_feedback_age_ms": "CAN feedback age (ms)"}
SEVERITY_COLOUR = {"debug": "0.6", "info": "#1f77b4", "warning": "#ff7f0e", "error": "#d62728", "critical": "#7f0000"}


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("plot", help="draw the figure set of a recording (trajectory, states, inputs, "
                                           "authority, estimates, link health)")
    p.add_argument("file", metavar="FILE.mcap")
    p.add_argument("--out", metavar="DIR", required=True, help="directory for the PNG files")
    p.add_argument("--scenario", help="scenario file or packaged name (default: the one stored in the recording)")
    p.add_argument("--no-overview", action="store_true", help="skip overview.png (the one-page figure)")
    p.set_defaults(handler=run)


def _loop(run: RecordedRun, scenario_arg: str | None):
    if scenario_arg:
        return load(scenario_arg).closed_loop()[0]
    if not run.scenario_toml:
        raise ScenarioError("the recording holds no scenario; give one with --scenario")
    return parse(tomllib.loads(run.scenario_toml)).closed_loop()[0]


def _save(fig, out: Path, name: str, written: list[Path], dpi: int = DPI) -> None:
    path = out / name
    fig.savefig(path, dpi=dpi)
    written.append(path)


def _single(panel, trace, loop, title: str, size=(11, 4.2), time_axis: bool = True):
    fig = Figure(figsize=size, layout="constrained")
    ax = fig.add_subplot()
    panel(ax, trace, loop)
    if time_axis:
        figures.time_axis(ax)
    fig.suptitle(title, fontsize=11)
    return fig, ax


def trajectory_figure(run: RecordedRun, loop, title: str):
    fig = Figure(figsize=(8, 7.5), layout="constrained")
    ax = fig.add_subplot()
    if run.trace is not None:
        figures.trajectory_panel(ax, run.trace, loop, "Path in the feasible set (controller's estimate q)")
    if len(run.truth_q):
        if run.trace is None:
            xy = run.truth_q[:, :2]
            lo, hi = xy.min(axis=0), xy.max(axis=0)
            pad = max(0.5, float((hi - lo).max()) * 0.3)
            figures.draw_feasible_set(ax, loop.feasible, (lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad))
            ax.set_aspect("equal", adjustable="box")
            ax.set_title("Path in the feasible set (ground truth)")
            names = loop.model.coordinate_names
            ax.set_xlabel(names[0]), ax.set_ylabel(names[1])
            ax.plot(*run.truth_q[0, :2], "o", color="k", mfc="white", ms=8, zorder=7)
            ax.plot(*run.truth_q[-1, :2], "s", color="k", ms=7, zorder=7)
        ax.plot(run.truth_q[:, 0], run.truth_q[:, 1], color="0.2", lw=0.9, alpha=0.8, label="q, ground truth", zorder=5)
        handles, _ = ax.get_legend_handles_labels()
        old = ax.get_legend()
        extra = [h for h in handles if h.get_label() == "q, ground truth"]
        if old is not None:
            ax.legend(handles=old.legend_handles + extra, loc="best", framealpha=0.9, fontsize=8)
        else:
            ax.legend(handles=extra, loc="best", fontsize=8)
    fig.suptitle(title, fontsize=11)
    return fig


def link_figure(run: RecordedRun, title: str):
    fig = Figure(figsize=(12, 10), layout="constrained")
    axes = fig.subplots(len(LINK_FIELDS) + 1, 1, sharex=True)
    for ax, name in zip(axes, LINK_FIELDS):
        if len(run.link_t):
            ax.plot(run.link_t, run.link[name], color="#1f77b4", lw=1.1)
        ax.set_ylabel(LINK_LABELS[name], fontsize=8.5)
        ax.grid(True, alpha=0.3)
    axes[0].set_title("Link health (RobotState.link)" + ("" if len(run.link_t) else ": no RobotState recorded"))
    ax = axes[-1]
    for i, (topic, times) in enumerate(sorted(run.topic_times.items())):
        if len(times) < 2:
            continue
        edges = np.arange(0.0, times[-1] + 0.5, 0.5)
        counts, _ = np.histogram(times, bins=edges)
        ax.step(edges[:-1], counts / 0.5, where="post", color=f"C{i % 10}", lw=1.1,
                label=topic.split("/", 3)[-1] if topic.count("/") >= 3 else topic)
    for t, kind, severity, _text in run.events:
        colour = SEVERITY_COLOUR.get(severity, "0.5")
        for axis in axes:
            axis.axvline(t, color=colour, lw=0.8, ls=":", alpha=0.8)
        ax.text(t, 1.0, kind, transform=ax.get_xaxis_transform(), rotation=90, fontsize=7, color=colour,
                va="top", ha="right")
    ax.set_ylabel("messages/s (0.5 s bins)", fontsize=8.5)
    ax.set_title("Message rate per topic; events as dotted lines")
    ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8)
    figures.time_axis(ax)
    ax.set_xlabel("t (s, recorder log time)")
    fig.suptitle(title, fontsize=12)
    return fig


def plot_recording(path: Path | str, out: Path | str, scenario: str | None = None,
                   overview: bool = True, dpi: int = DPI) -> list[Path]:
    """Draw every figure the recording has data for; returns the files written."""
    run = load_run(path)
    loop = _loop(run, scenario)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    title = run.title or Path(path).name
    written: list[Path] = []
    with matplotlib.rc_context(figures.FONT):
        if run.trace is not None or len(run.truth_q):
            _save(trajectory_figure(run, loop, title), out, "trajectory.png", written, dpi)
        if run.trace is not None:
            trace = run.trace
            for name, panel in (("states", figures.states_panel), ("inputs", figures.inputs_panel),
                                ("authority", figures.authority_panel), ("estimates", figures.estimates_panel),
                                ("margin", figures.margin_panel)):
                fig, _ = _single(panel, trace, loop, title)
                _save(fig, out, f"{name}.png", written, dpi)
            if overview:
                _save(figures.run_figure(trace, loop, title), out, "overview.png", written, dpi)
        _save(link_figure(run, title), out, "link.png", written, dpi)
    return written


def run(args) -> int:
    try:
        written = plot_recording(args.file, args.out, args.scenario, overview=not args.no_overview)
    except (OSError, ValueError, ScenarioError) as exc:   # NotARecording, TOMLDecodeError are ValueErrors
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2
    print(f"{PROG}: {len(written)} figures in {args.out}: {', '.join(p.name for p in written)}")
    return 0
