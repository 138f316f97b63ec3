"""Summaries as JSON (services/summary_output.py): strict (a figure that could not be measured is null) and
written atomically (a reader finds the old file or the new one, never a part, and no temporary file stays)."""
import json
import math

import numpy as np
import pytest

from sharedctl.services.summary_output import read_json, write_json


def strict(text):
    return json.loads(text, parse_constant=lambda name: pytest.fail(f"{name} in the JSON"))


def test_non_finite_numbers_are_written_as_null_and_numpy_scalars_as_numbers(tmp_path):
    path = tmp_path / "s.json"
    write_json(path, {"p99_us": math.nan, "max": [math.inf, -math.inf, 1.5], "n": np.int64(3),
                      "mean": np.float32(0.5), "pair": (1, "a")})
    assert strict(path.read_text()) == {"p99_us": None, "max": [None, None, 1.5], "n": 3, "mean": 0.5,
                                        "pair": [1, "a"]}


def test_a_summary_replaces_the_old_one_whole_and_leaves_no_temporary_file(tmp_path):
    path = tmp_path / "s.json"
    write_json(path, {"ticks": 1})
    write_json(path, {"ticks": 2})
    assert read_json(path) == {"ticks": 2} and [p.name for p in tmp_path.iterdir()] == ["s.json"]


def test_a_summary_that_cannot_be_written_leaves_the_old_one_as_it_was(tmp_path):
    path = tmp_path / "s.json"
    write_json(path, {"ticks": 1})
    with pytest.raises(TypeError):
        write_json(path, {"ticks": object()})
    assert read_json(path) == {"ticks": 1} and [p.name for p in tmp_path.iterdir()] == ["s.json"]


def test_a_missing_or_unreadable_summary_reads_as_none(tmp_path):
    (tmp_path / "half.json").write_text('{"ticks": ')
    assert read_json(tmp_path / "none.json") is None and read_json(tmp_path / "half.json") is None


def test_a_summary_written_to_a_named_pipe_goes_through_it_and_leaves_the_pipe_a_pipe(tmp_path):
    """`--json /dev/null` or a pipe: the target is written, never replaced by a renamed file."""
    import os
    import stat
    import threading

    pipe = tmp_path / "summary.fifo"
    os.mkfifo(pipe)
    received = []
    reader = threading.Thread(target=lambda: received.append(pipe.read_text()), daemon=True)
    reader.start()
    write_json(pipe, {"ticks": 3})
    reader.join(timeout=5)
    assert received and json.loads(received[0]) == {"ticks": 3}
    assert stat.S_ISFIFO(os.stat(pipe).st_mode)
    assert [p.name for p in tmp_path.iterdir()] == ["summary.fifo"]


def test_a_summary_gets_the_mode_a_plainly_created_file_would(tmp_path):
    """Readable as `open(path, "w")` would leave it under the process's umask (not the temporary file's 0600)."""
    import os
    import stat

    plain = tmp_path / "plain.json"
    plain.write_text("{}")
    write_json(tmp_path / "summary.json", {"ticks": 1})
    assert stat.S_IMODE(os.stat(tmp_path / "summary.json").st_mode) == stat.S_IMODE(os.stat(plain).st_mode)
