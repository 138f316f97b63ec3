# A fresh machine needs only python3 (>= 3.11) with venv: everything else comes from requirements/,
# exact versions with their hashes (pip refuses any file whose hash is not listed).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test setup clean paper lock

setup: $(STAMP)

# requirements/test.lock is requirements/runtime.lock plus every extra (plots, baselines, test), with
# pip and the build backend: the project is then installed without build isolation, so nothing is
# fetched unhashed.
$(STAMP): pyproject.toml requirements/runtime.lock requirements/test.lock
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --require-hashes -r requirements/test.lock
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

demo: $(STAMP)
	mkdir -p out
	$(BIN)/sharedctl demo --scenario paper_convex --json out/demo.json

# Lint first (configuration in pyproject.toml, [tool.ruff]). Then both test phases at once
# (tests/run_suite.py): the tests that start processes or open sockets (marked `processes`) one
# at a time in the foreground, and the pure tests (simulations, codecs) on two workers, a file at
# a time, in the background at the lowest priority — their own session's autogroup at nice 19 —
# so that they take only the CPU the processes leave and the processes' timing is not disturbed.
# (The packaged scenarios' runs are computed once per run and shared by the workers:
# tests/helpers.py.) Each phase lists its slowest tests; the pure phase's report comes last.
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/python tests/run_suite.py

paper: $(STAMP)
	$(BIN)/sharedctl paper --out docs/paper

# Regenerates the locks from pyproject.toml's ranges (each lock's first lines repeat its command).
# uv keeps every version already pinned that the ranges still allow; to move one, add
# --upgrade-package NAME to its line. The test lock is constrained to the runtime lock, so the
# two agree on every package they share. uv itself comes from requirements/tools.lock.
LOCK_VENV := build/lock-venv
UV        := $(LOCK_VENV)/bin/uv

lock: $(UV)
	$(UV) pip compile pyproject.toml requirements/build.in --universal --python-version 3.11 --generate-hashes -o requirements/runtime.lock
	$(UV) pip compile pyproject.toml requirements/build.in --all-extras -c requirements/runtime.lock --universal --python-version 3.11 --generate-hashes -o requirements/test.lock
	$(UV) pip compile requirements/tools.in --universal --python-version 3.11 --generate-hashes -o requirements/tools.lock

$(UV): requirements/tools.lock
	$(PYTHON) -m venv $(LOCK_VENV)
	$(LOCK_VENV)/bin/python -m pip install --quiet --require-hashes -r requirements/tools.lock
	touch $(UV)

clean:
	rm -rf $(VENV) build *.egg-info
