"""The demo's children write their exit summaries as JSON into its log directory (services/demo/command.py)."""
from sharedctl.services.demo.command import _json


def test_a_summary_left_by_an_earlier_run_is_removed_before_the_child_starts(tmp_path):
    """A child that dies without writing a summary must have none, not the previous run's."""
    stale = tmp_path / "controller.json"
    stale.write_text('{"ticks": 2345}')
    argv = _json("controller", tmp_path)
    assert argv == ["--json", str(stale)]
    assert not stale.exists()
