"""A run's summary as JSON: how every process and study hands its results to another module.

`write_json(path, summary)` writes it atomically (a temporary file beside it, then a rename: a reader
never sees half of one) and strictly (NaN and ±inf, figures that could not be measured, as null);
`read_json(path)` reads one back, None if there is none. `emit` is `--json OUT` beside a printed table.
Nothing reads another process's printed lines.
"""
from __future__ import annotations

import dataclasses
import json
import math
import numbers
import os
import tempfile
from pathlib import Path


def finite_or_null(value):
    """`value` with every non-finite number as None, numpy scalars as Python numbers, dataclasses as dicts."""
    if isinstance(value, dict):
        return {k: finite_or_null(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_or_null(v) for v in value]
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        number = float(value)
        return number if math.isfinite(number) else None
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return finite_or_null(dataclasses.asdict(value))
    return value


def to_json(summary, indent: int = 2, default=None) -> str:
    """Strict JSON text of `summary` (`default`: as json.dumps's, for values of other types)."""
    return json.dumps(finite_or_null(summary), indent=indent, allow_nan=False, default=default)


def write_json(path, summary, indent: int = 2, default=None) -> None:
    """`summary` as JSON at `path`, atomically: written to a temporary file in the same folder, then renamed.

    A `path` that exists and is not a regular file (`/dev/null`, `/dev/stdout`, a named pipe) is written to
    as it is: renaming a file over a device would replace the device."""
    path = Path(path)
    text = to_json(summary, indent, default) + "\n"
    if path.exists() and not path.is_file():
        with open(path, "w") as out:
            out.write(text)
        return
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())      # as open() would create it (mkstemp makes it 0600)
        with os.fdopen(fd, "w") as out:
            out.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _umask() -> int:
    """The process's umask, read without changing it where Linux says it (setting it, even back, races
    with other threads creating files)."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0)
    os.umask(mask)
    return mask


def read_json(path) -> dict | None:
    """The JSON object at `path`, None if there is no file or it holds no JSON object."""
    try:
        value = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return value if isinstance(value, dict) else None


def emit(summary: dict, json_target: str | None, print_table) -> None:
    """`--json -` prints the JSON only; otherwise the table is printed and the JSON written if asked."""
    if json_target == "-":
        print(to_json(summary))
        return
    if json_target:
        write_json(json_target, summary)
    print_table(summary)
