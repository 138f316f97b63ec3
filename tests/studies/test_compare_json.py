"""`sharedctl compare --json`: the contracted shape, on a tiny run (in process); the price of the fail-safe stop.

Oracle for `backup_price`: the scenario parsed again with `[backup] enabled = false` and run as
`shared` (the scenario file's own switch, not the `shared-nobackup` variant under test).
"""
import json
from types import SimpleNamespace

import pytest

from sharedctl.baselines.comparison import CONTROL_PERIOD, STRATEGIES, build_strategy, run
from sharedctl.baselines.comparison_metrics import summarize
from sharedctl.baselines.operator_link import IDEAL
from sharedctl.scenario import parse
from sharedctl.services.studies.compare.command import compare, document, handle
from sharedctl.services.studies.compare.price import PRICE_METRICS
from sharedctl.services.studies.compare.report import write_report
from sharedctl.services.studies.compare.scenarios import _packaged, scenario_set

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
        assert r["time_to_goal"] is None or 0.0 <= r["time_to_goal"] < 0.1
        assert r["steps"] == 50
    assert doc["goal_tolerance"] == 0.1
    price = doc["backup_price"]                             # one entry per scenario and condition
    assert [(e["scenario"], e["condition"]) for e in price] == \
        [(r["scenario"], r["condition"]) for r in rows if r["strategy"] == "shared"]
    assert all(set(e["with"]) == set(e["without"]) == set(PRICE_METRICS) for e in price)
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


PRICE_RUN = 3.0   # s: the adversarial operator meets the top face after ~2 s


@pytest.fixture(scope="module")
def wall_price():
    """(entry of backup_price, document, outcomes) for the adversarial wall, ideal link, its first PRICE_RUN s."""
    entries = [e for e in scenario_set(duration=PRICE_RUN) if e.scenario.name == "adversarial-wall"]
    outcomes = compare(entries, ("shared", "shared-nobackup"), (IDEAL,))
    doc = document(outcomes, quick=True)
    return doc["backup_price"][0], doc, outcomes


def _paper_loop_metrics(name: str, duration: float) -> dict:
    data = _packaged(name)
    data["backup"] = {"enabled": False}
    loop, q0, v0 = parse(data).closed_loop()
    assert loop.backup is None
    trace = run(build_strategy("shared", loop), loop, q0, v0, duration, IDEAL)
    return summarize(trace, loop.feasible, CONTROL_PERIOD)


def test_without_the_backup_safe_sets_is_the_scenario_with_backup_disabled(wall_price):
    entry, _, _ = wall_price
    oracle = _paper_loop_metrics("adversarial_wall", PRICE_RUN)
    assert entry["backup_model"] is True
    assert entry["without"] == {k: oracle[k] for k in PRICE_METRICS}


def test_the_backup_safe_sets_take_authority_earlier_where_the_machine_acted(wall_price):
    entry, _, _ = wall_price
    without, with_ = entry["without"], entry["with"]
    assert without["human_authority"] < 1.0                # the machine acted in the paper's loop too
    assert with_["human_authority"] < without["human_authority"]
    assert with_["violations"] == without["violations"] == 0


def test_where_the_machine_never_acted_with_and_without_are_the_same():
    entries = [e for e in scenario_set(duration=1.0) if e.scenario.name == "paper-nonconvex"]
    entry = document(compare(entries, ("shared", "shared-nobackup"), (IDEAL,)), quick=True)["backup_price"][0]
    assert entry["without"]["human_authority"] == 1.0       # the operator alone drove, in both
    assert entry["with"] == entry["without"]


def test_the_report_tables_the_price_from_the_json(tmp_path, wall_price):
    entry, doc, outcomes = wall_price
    text = write_report(outcomes, doc, tmp_path).read_text()
    without, with_ = entry["without"], entry["with"]
    line = next(x for x in text.splitlines() if x.startswith("| adversarial-wall | ideal | "))
    assert "## The price of the fail-safe stop" in text
    assert line.split(" | ")[2] == f"{without['human_authority']:.3f} → {with_['human_authority']:.3f}"
