"""`sharedctl paper` writes Figures 1–8 and a summary; `run_figure` draws one run.

The command runs long enough for the figures to show what the paper's figures are about: the
operator's line first brings the machine in at t ≈ 8.8 s (non-convex) and t ≈ 9.8 s (convex), so
DURATION_S = 11 s covers each run's first intervention and the minimum dwell after it. The
figures' plotted arrays, their titles and the runs they were drawn from are read back from what
the command hands to the figure module; the table is checked against the metrics recomputed from
those traces (`sharedctl.metrics`, and numpy by hand where a metric is one line), the captions
against the equation numbers of docs/control.md §4–6, typed here by hand.
"""
from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest
from matplotlib import image

from sharedctl.metrics import handover, machine_authority_time, peak_norm, rms_norm, share_above, summarize
from sharedctl.services import cli
from sharedctl.services.studies import figures
from sharedctl.services.studies.paper import command as paper_command
from sharedctl.services.studies.paper.laws import ConfigurationMismatch, describe
from sharedctl.services.studies.figures import feasible_mask, run_figure
from sharedctl.services.scenario_files import load
from sharedctl.sharing import Authority, SharingParameters
from sharedctl.simulator import MachineController, make_controller, simulate

DURATION_S = 11.0
TRAJECTORY_FIGURES = ("fig1_convex_trajectory.png", "fig5_nonconvex_trajectory.png")
RESPONSE_FIGURES = ("fig2_convex_ce.png", "fig3_convex_nce.png", "fig4_convex_of.png",
                    "fig6_nonconvex_ce.png", "fig7_nonconvex_nce.png", "fig8_nonconvex_of.png")
K_F_LABEL = "$k_f$ (machine weight)"
RESPONSE_GROUPS = {"convex": ("fig2_convex_ce.png", "fig3_convex_nce.png", "fig4_convex_of.png"),
                   "nonconvex": ("fig6_nonconvex_ce.png", "fig7_nonconvex_nce.png", "fig8_nonconvex_of.png")}
#: what a caption of each configuration must say (docs/control.md §4.1–4.3, §6), and must not
LAW_TOKENS = {"ce": ("(46)", "(12)"), "nce": ("(46)", "composite", "§4.2", "(14)–(15)"),
              "of": ("(47)", "(25)–(29)", "observer (40)", "barrier form in the hazardous set")}
FOREIGN_TOKENS = {"ce": ("(47)", "composite", "(25)"), "nce": ("(47)", "(25)"), "of": ("(46)", "composite")}
#: the simulated robot's per-wheel drive limit (services/robot/plant.py; the paper scenarios set no [robot_sim])
DRIVE_LIMIT_NM = 60.0


def plotted_lines(figure) -> dict:
    """{axes title: [(label, marker, x, y), …]} of every Line2D the figure draws."""
    return {ax.get_title(): [(line.get_label(), line.get_marker(), np.asarray(line.get_xdata(), dtype=float),
                              np.asarray(line.get_ydata(), dtype=float)) for line in ax.get_lines()]
            for ax in figure.axes}


@pytest.fixture(scope="module")
def paper_dir(tmp_path_factory):
    """Run the command once; keep each figure's plotted lines and title (read after the command saved
    it), and the runs (traces, loops) the figures were drawn from."""
    out = tmp_path_factory.mktemp("paper")
    plotted: dict = {}
    drawing = figures.paper_figures

    def recording(runs):
        plotted["runs"] = {(run.scenario, run.controller): run for run in runs}
        for paper_figure in drawing(runs):
            yield paper_figure
            plotted[paper_figure.filename] = plotted_lines(paper_figure.figure)
            plotted["titles", paper_figure.filename] = paper_figure.figure.get_suptitle()

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(figures, "paper_figures", recording)
        code = cli.main(["paper", "--out", str(out), "--duration", str(DURATION_S)])
    return out, code, plotted


def first_machine_sample(lines) -> float:
    """t of the first sample with k_f > 0, from a response figure's plotted authority panel."""
    (authority,) = [title for title in lines if "Authority" in title]
    (_, _, t, k_f), = [line for line in lines[authority] if line[0] == K_F_LABEL]
    return float(t[np.flatnonzero(k_f > 0.0)[0]])


def panel_arrays(lines, key: str) -> tuple[np.ndarray, np.ndarray]:
    """(t, every y array stacked) of the panel whose title contains `key`."""
    (title,) = [title for title in lines if key in title]
    series = lines[title]
    return series[0][2], np.array([y for _, _, x, y in series if x.size == series[0][2].size])


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


@pytest.mark.parametrize("scenario", sorted(RESPONSE_GROUPS))
@pytest.mark.parametrize("panel", ["$u_f$", "θ̂(t)"])
def test_the_three_configurations_plot_different_arrays_once_the_machine_acts(paper_dir, scenario, panel):
    """Figures 2, 3, 4 (6, 7, 8) draw three different runs: from the first machine sample on, the plotted
    machine force and parameter estimates of any two configurations differ. (Before it the operator
    alone acts: a run that ends there would draw the same arrays three times.)"""
    _, _, plotted = paper_dir
    after = {}
    for name in RESPONSE_GROUPS[scenario]:
        t, arrays = panel_arrays(plotted[name], panel)
        after[name] = arrays[:, t >= first_machine_sample(plotted[name])]
    for a, b in itertools.combinations(RESPONSE_GROUPS[scenario], 2):
        assert not np.array_equal(after[a], after[b], equal_nan=True), (a, b)


@pytest.mark.parametrize("name", RESPONSE_FIGURES)
def test_each_response_figure_title_and_caption_name_the_law_of_its_configuration(paper_dir, name):
    out, _, plotted = paper_dir
    controller = name.removesuffix(".png").split("_")[-1]
    captions = {f["file"]: f["caption"] for f in json.loads((out / "summary.json").read_text())["figures"]}
    markdown = (out / "summary.md").read_text()
    (line,) = [line for line in markdown.splitlines() if line.startswith(f"- `{name}`")]
    for text in (captions[name], line, plotted["titles", name].replace("\n", " ")):
        assert f"— {controller}: " in text
        assert all(token in text for token in LAW_TOKENS[controller]), text
        assert not any(token in text for token in FOREIGN_TOKENS[controller]), text


@pytest.mark.parametrize("name", TRAJECTORY_FIGURES)
def test_each_trajectory_caption_names_the_law_of_every_path(paper_dir, name):
    out, _, _ = paper_dir
    caption = {f["file"]: f["caption"] for f in json.loads((out / "summary.json").read_text())["figures"]}[name]
    listed = caption[caption.index("(ce — ") + 1:caption.rindex(")")]        # "(ce — …; nce — …; of — …)"
    laws = dict(part.split(" — ", 1) for part in listed.split("; "))
    assert list(laws) == ["ce", "nce", "of"]
    for controller, tokens in LAW_TOKENS.items():
        assert all(token in laws[controller] for token in tokens), laws[controller]
        assert not any(token in laws[controller] for token in FOREIGN_TOKENS[controller]), laws[controller]


def test_summary_json_says_what_each_configuration_runs(paper_dir):
    out, _, _ = paper_dir
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["configurations"]) == ["ce", "nce", "of"]
    for controller, law in summary["configurations"].items():
        assert all(token in law for token in LAW_TOKENS[controller]), law
    for record in summary["runs"]:
        assert record["law"] == summary["configurations"][record["controller"]]


def test_the_table_equals_the_metrics_recomputed_from_the_traces(paper_dir):
    out, _, plotted = paper_dir
    for record in json.loads((out / "summary.json").read_text())["runs"]:
        run = plotted["runs"][record["scenario"].removeprefix("paper-"), record["controller"]]
        trace, dt = run.trace, record["dt"]
        expected = {**summarize(trace, dt), "u_s_peak": peak_norm(trace.u_s), "u_s_rms": rms_norm(trace.u_s),
                    "wheel_torque_peak": handover(trace)["peak_wheel_torque"], "wheel_torque_limit": DRIVE_LIMIT_NM,
                    "wheel_torque_over_limit": share_above(trace.tau, DRIVE_LIMIT_NM),
                    "machine_authority_time": machine_authority_time(trace, dt)}
        expected = {k: None if isinstance(v, float) and not math.isfinite(v) else v for k, v in expected.items()}
        assert {k: record[k] for k in expected} == expected, (record["scenario"], record["controller"])


def test_the_tables_sizes_are_the_traces_by_hand(paper_dir):
    """The input and torque columns, against numpy on the trace (the runs stay finite)."""
    out, _, plotted = paper_dir
    for record in json.loads((out / "summary.json").read_text())["runs"]:
        trace = plotted["runs"][record["scenario"].removeprefix("paper-"), record["controller"]].trace
        norms = np.linalg.norm(trace.u_s, axis=1)
        assert record["u_s_peak"] == pytest.approx(norms.max(), rel=1e-12)
        assert record["u_s_rms"] == pytest.approx(np.sqrt(np.mean(norms**2)), rel=1e-12)
        assert record["wheel_torque_peak"] == pytest.approx(np.abs(trace.tau).max(), rel=1e-12)
        assert record["wheel_torque_over_limit"] == pytest.approx(
            np.mean(np.abs(trace.tau).max(axis=1) > DRIVE_LIMIT_NM), abs=1e-15)
        machine = np.count_nonzero(trace.authority == int(Authority.MACHINE))
        assert machine > 0 and record["machine_authority_time"] == pytest.approx(machine * record["dt"], rel=1e-12)


def test_remark_3_sentence_states_the_theta_errors_of_ce_and_nce_from_the_json(paper_dir):
    out, _, _ = paper_dir
    runs = {(r["scenario"], r["controller"]): r for r in json.loads((out / "summary.json").read_text())["runs"]}
    markdown = (out / "summary.md").read_text()
    for scenario in ("paper-convex", "paper-nonconvex"):
        ce, nce = runs[scenario, "ce"]["theta_error"], runs[scenario, "nce"]["theta_error"]
        (line,) = [line for line in markdown.splitlines() if line.startswith(f"- {scenario}: θ error at the end")]
        assert f"ce {ce:.3g}, nce {nce:.3g}" in line
        assert ("nce's is lower" if nce < ce else "ce's is lower") in line


def test_describe_refuses_a_controller_that_is_not_the_described_one():
    ce, nce = make_controller("ce"), make_controller("nce")
    with pytest.raises(ConfigurationMismatch):
        describe("nce", ce)                                          # (12) is not the composite law
    with pytest.raises(ConfigurationMismatch):
        describe("nce", MachineController(nce.tracking, ce.tracking))  # (12), not its own law, in the hazardous set
    of = make_controller("of")
    with pytest.raises(ConfigurationMismatch):
        describe("of", MachineController(of.tracking, of.tracking, of.observer))   # no hazardous-set law described


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
