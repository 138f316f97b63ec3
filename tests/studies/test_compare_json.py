"""`sharedctl compare --json`: the contracted shape, on a tiny run (in process)."""
import json
from types import SimpleNamespace

from sharedctl.baselines.comparison import STRATEGIES
from sharedctl.services.studies.compare.command import compare, document, handle
from sharedctl.services.studies.compare.report import write_report
from sharedctl.services.studies.compare.scenarios import scenario_set

METRICS = ("violations", "min_margin", "tracking_error", "human_authority", "interventions", "control_effort",
           "jerk_rms")


def test_every_row_has_strategy_scenario_and_the_metrics(tmp_path):
    out = tmp_path / "compare.json"
    args = SimpleNamespace(quick=True, json=str(out), report=None, strategies=",".join(STRATEGIES), duration=0.1)
    assert handle(args) == 0
    doc = json.loads(out.read_text())
    rows = doc["results"]
    assert len(rows) == len(STRATEGIES) * len(doc["scenarios"]) * len(doc["conditions"])
    assert {r["strategy"] for r in rows} == set(STRATEGIES)
    assert any(r["base_scenario"] == "adversarial-wall" for r in rows)
    assert len({(r["strategy"], r["scenario"]) for r in rows}) == len(rows)     # (strategy, scenario) is a key
    for r in rows:
        for key in METRICS:
            assert isinstance(r[key], (int, float)), (key, r)
        assert r["steps"] == 50
    sensitivity = doc["model_sensitivity"]                  # mux and cbf with θ̂ = s·θ, adversarial scenarios
    assert {r["strategy"] for r in sensitivity} == {"mux", "cbf"}
    assert all(r["base_scenario"].startswith("adversarial") and r["theta_scale"] != 1.0 for r in sensitivity)


def test_the_report_is_written_with_its_figures(tmp_path):
    entries = scenario_set(duration=0.1)[:1]
    outcomes = compare(entries, ("human", "shared"))
    path = write_report(outcomes, document(outcomes, quick=True), tmp_path)
    text = path.read_text()
    assert "## Where each strategy wins" in text and "`shared` stayed inside in every run" in text
    assert (tmp_path / "metrics.png").stat().st_size > 0
    assert (tmp_path / "paths_adversarial-wall.png").stat().st_size > 0


def test_an_unknown_strategy_is_refused():
    args = SimpleNamespace(quick=True, json=None, report=None, strategies="human,teleport", duration=0.1)
    assert handle(args) == 2
