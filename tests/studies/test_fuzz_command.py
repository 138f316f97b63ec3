"""`sharedctl fuzz`: on-demand fuzz campaign with a summary table and a meaningful exit code."""
from __future__ import annotations

import argparse

import pytest
from rich.console import Console

from sharedctl.protocol.fuzz import FuzzReport
from sharedctl.services.studies.fuzz import command as fuzz_command


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="sharedctl")
    fuzz_command.add_parser(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(argv)


def run(argv: list[str]) -> tuple[int, str]:
    console = Console(record=True, width=120)
    code = fuzz_command.run(parse(argv), console)
    return code, console.export_text()


def test_fuzz_sub_command_registers_its_handler():
    assert parse(["fuzz"]).handler is fuzz_command.run


def test_defaults_are_100k_inputs_seed_0_all_decoders():
    args = parse(["fuzz"])
    assert (args.count, args.seed, args.decoder) == (100_000, 0, "all")


def test_clean_campaign_exits_zero():
    assert run(["fuzz", "--count", "300", "--seed", "5"])[0] == 0


def test_summary_table_has_one_row_per_decoder_with_zero_escapes():
    _, text = run(["fuzz", "--count", "300"])
    rows = [line for line in text.splitlines() if line.startswith("│")]
    assert [row.split("│")[1].strip() for row in rows] == ["can", "message", "key", "attachment"]


def test_summary_table_reports_the_input_count():
    _, text = run(["fuzz", "--count", "250", "--decoder", "key"])
    assert "│ key     │    250 │" in text


def test_decoder_option_restricts_the_campaign_to_one_decoder():
    _, text = run(["fuzz", "--count", "100", "--decoder", "can"])
    assert ("│ can" in text, "│ message" in text) == (True, False)


def test_unknown_decoder_is_a_usage_error():
    with pytest.raises(SystemExit):
        parse(["fuzz", "--decoder", "zenoh"])


def test_zero_count_is_a_usage_error():
    with pytest.raises(SystemExit):
        parse(["fuzz", "--count", "0"])


def test_an_escape_makes_the_exit_code_non_zero(monkeypatch):
    leaky = FuzzReport("can", inputs=10, typed_errors=9, escapes=1, examples=["can: KeyError on frame"])
    monkeypatch.setattr(fuzz_command, "run_campaign", lambda decoder, count, seed: leaky)
    assert run(["fuzz", "--decoder", "can"])[0] == 1
