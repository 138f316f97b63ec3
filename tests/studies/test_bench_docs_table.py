"""docs/performance.md's "Latest figures" table is the output of `bench.docs_table` on the recorded runs."""
import json
from pathlib import Path

from sharedctl.services.studies.bench import docs_table

ROOT = Path(__file__).resolve().parents[2]


def test_a_cell_joins_figures_brackets_the_bare_loop_and_names_the_extent():
    run = {"a": {"p50": 1234.4, "p99": 2000.6}, "floor": {"p50": 99.96}, "robots": 8192, "missing": None}
    assert docs_table.cell(run, ["a.p50", "a.p99", "|floor.p50"], 0) == "1,234 / 2,001 [100]"
    assert docs_table.cell(run, ["a.p50", "@robots"], (1,)) == "1,234.4 (8,192)"
    assert docs_table.cell(run, ["missing", "absent.key"], 2) == "— / —"


def test_the_page_holds_the_table_regenerated_from_the_recorded_runs():
    recorded = ROOT / "docs" / "performance"
    runs = [json.loads((recorded / name).read_text()) for name in ("bench.json", "bench-quick.json")]
    expected = docs_table.table(*runs)
    page = (ROOT / "docs" / "performance.md").read_text()
    assert expected in page, "regenerate the table: python -m sharedctl.services.studies.bench.docs_table …"
