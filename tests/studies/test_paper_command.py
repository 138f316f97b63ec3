"""`sharedctl paper` writes Figures 1–8 and a summary; `run_figure` draws one run.

The command runs long enough for the figures to show what the paper's figures are about: the
operator's line first brings the machine in at t ≈ 8.8 s (non-convex) and t ≈ 9.8 s (convex), so
DURATION_S = 11 s covers each run's first intervention and the minimum dwell after it. The
figures' plotted arrays are read back from the figure objects the command draws.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from matplotlib import image

from sharedctl.services import cli
from sharedctl.services.studies import figures
from sharedctl.services.studies.paper import command as paper_command
from sharedctl.services.studies.figures import feasible_mask, run_figure
from sharedctl.services.scenario_files import load
from sharedctl.sharing import SharingParameters
from sharedctl.simulator import simulate

DURATION_S = 11.0
TRAJECTORY_FIGURES = ("fig1_convex_trajectory.png", "fig5_nonconvex_trajectory.png")
RESPONSE_FIGURES = ("fig2_convex_ce.png", "fig3_convex_nce.png", "fig4_convex_of.png",
                    "fig6_nonconvex_ce.png", "fig7_nonconvex_nce.png", "fig8_nonconvex_of.png")
K_F_LABEL = "$k_f$ (machine weight)"


def plotted_lines(figure) -> dict:
    """{axes title: [(label, marker, x, y), …]} of every Line2D the figure draws."""
    return {ax.get_title(): [(line.get_label(), line.get_marker(), np.asarray(line.get_xdata(), dtype=float),
                              np.asarray(line.get_ydata(), dtype=float)) for line in ax.get_lines()]
            for ax in figure.axes}


@pytest.fixture(scope="module")
def paper_dir(tmp_path_factory):
    """Run the command once; keep each figure's plotted lines (read after the command saved it)."""
    out = tmp_path_factory.mktemp("paper")
    plotted: dict = {}
    drawing = figures.paper_figures

    def recording(runs):
        for paper_figure in drawing(runs):
            yield paper_figure
            plotted[paper_figure.filename] = plotted_lines(paper_figure.figure)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(figures, "paper_figures", recording)
        code = cli.main(["paper", "--out", str(out), "--duration", str(DURATION_S)])
    return out, code, plotted


def test_paper_exits_zero_when_every_run_is_safe_and_finite(paper_dir):
    _, code, _ = paper_dir
    assert code == 0


@pytest.mark.parametrize("name", TRAJECTORY_FIGURES + RESPONSE_FIGURES)
def test_paper_writes_each_figure_as_a_decodable_png_of_the_expected_size(paper_dir, name):
    out, _, _ = paper_dir
    path = out / name
    assert path.stat().st_size > 20_000
    width_in, height_in = (15, 10) if name in TRAJECTORY_FIGURES else (15, 13)
    pixels = image.imread(path)
    assert pixels.shape == (height_in * paper_command.DPI, width_in * paper_command.DPI, 4)
    assert pixels[..., :3].std() > 0.05   # not a blank page


def test_summary_markdown_has_one_table_row_per_scenario_and_controller(paper_dir):
    out, _, _ = paper_dir
    text = (out / "summary.md").read_text()
    for scenario in ("paper-convex", "paper-nonconvex"):
        for controller in ("ce", "nce", "of"):
            assert sum(line.startswith(f"| {scenario} | {controller} |") for line in text.splitlines()) == 1
    for name in TRAJECTORY_FIGURES + RESPONSE_FIGURES:
        assert f"`{name}`" in text


def test_summary_json_records_six_safe_runs_of_the_requested_length(paper_dir):
    out, _, _ = paper_dir
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ok"] is True
    assert [(r["scenario"], r["controller"]) for r in summary["runs"]] == [
        (s, c) for s in ("paper-convex", "paper-nonconvex") for c in ("ce", "nce", "of")
    ]
    for record in summary["runs"]:
        assert record["violations"] == 0
        assert record["finite"] is True
        assert record["steps"] == round(DURATION_S / record["dt"])
        assert len(record["theta_hat"]) == len(record["theta_true"]) == 3


def test_every_run_gives_the_machine_authority_at_some_sample(paper_dir):
    out, _, _ = paper_dir
    for record in json.loads((out / "summary.json").read_text())["runs"]:
        assert 0.0 < record["human_authority"] < 1.0, (record["scenario"], record["controller"])


@pytest.mark.parametrize("name", RESPONSE_FIGURES)
def test_response_figure_plots_the_first_machine_intervention_and_its_dwell(paper_dir, name):
    """The first sample with k_f > 0 (the machine took over) is found in the plotted k_f; every
    time series of the figure is plotted from t = 0 to at least Δt past it, and the plotted
    machine force u_f is non-zero there."""
    _, _, plotted = paper_dir
    lines = plotted[name]
    (authority,) = [title for title in lines if "Authority" in title]
    (_, _, t, k_f), = [line for line in lines[authority] if line[0] == K_F_LABEL]
    engaged = np.flatnonzero(k_f > 0.0)
    assert engaged.size > 0
    first = t[engaged[0]]
    dwell = SharingParameters().min_machine_dwell
    series = [(x, y) for panel in lines.values() for _, _, x, y in panel if x.size == t.size]
    assert len(series) >= 20                              # q, q̇, u_h, u_f, u_s, τ, k_h, k_f, θ̂ …
    for x, _ in series:
        assert x[0] == 0.0 and x[-1] >= first + dwell
    (machine_input,) = [title for title in lines if "$u_f$" in title]
    u_f = np.array([y for _, _, _, y in lines[machine_input]])
    assert np.any(u_f[:, (t >= first) & (t <= first + dwell)] != 0.0)


@pytest.mark.parametrize("name", TRAJECTORY_FIGURES)
def test_trajectory_figure_marks_machine_authority_on_each_path(paper_dir, name):
    _, _, plotted = paper_dir
    panels = {title: lines for title, lines in plotted[name].items() if "path by authority" in title}
    assert sorted(title.split(":")[0] for title in panels) == ["ce", "nce", "of"]
    for lines in panels.values():
        markers = [x for _, marker, x, _ in lines if marker == "o" and x.size > 1]   # machine samples (start: 1 point)
        assert markers, "no machine-authority sample on the path"


def test_paper_rejects_an_unknown_controller():
    with pytest.raises(SystemExit) as exc:
        cli.main(["paper", "--out", "unused", "--controllers", "ce,pid"])
    assert exc.value.code == 2


def test_feasible_mask_shades_the_nonconvex_set_but_not_the_obstacle():
    loop, _, _ = load("paper_nonconvex").closed_loop("ce")
    X, Y = np.meshgrid([-1.0, 1.0], [-1.0, 1.0])   # (x, y) = (−1,−1), (1,−1), (−1,1), (1,1)
    assert feasible_mask(loop.feasible, X, Y).tolist() == [[True, True], [True, False]]


def test_run_figure_draws_six_labelled_panels_for_a_short_run(tmp_path):
    scenario = load("paper_convex")
    loop, q0, v0 = scenario.closed_loop("ce")
    trace = simulate(loop, q0, v0, 0.5, scenario.dt)
    figure = run_figure(trace, loop, title="paper-convex — ce")
    titles = [ax.get_title() for ax in figure.axes]
    assert [t[:3] for t in titles] == ["(a)", "(f)", "(b)", "(c)", "(d)", "(e)"]
    assert all(ax.get_xlabel() and ax.get_ylabel() for ax in figure.axes)
    path = tmp_path / "run.png"
    figure.savefig(path, dpi=110)
    assert path.stat().st_size > 20_000
    assert image.imread(path).shape == (1100, 1650, 4)
