"""Writing a run's summary: JSON to a file or stdout (`--json OUT`, `-` for stdout), else a table."""
from __future__ import annotations

import json
from pathlib import Path


def emit(summary: dict, json_target: str | None, print_table) -> None:
    """`--json -` prints the JSON only; otherwise the table is printed and the JSON written if asked."""
    text = json.dumps(summary, indent=2)
    if json_target == "-":
        print(text)
        return
    if json_target:
        Path(json_target).write_text(text + "\n")
    print_table(summary)
