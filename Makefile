# A fresh machine needs only python3 (>= 3.11) with venv: everything else comes from requirements.lock.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test setup clean paper

setup: $(STAMP)

$(STAMP): pyproject.toml requirements.lock
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip==26.3
	$(BIN)/python -m pip install --quiet -r requirements.lock
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

demo: $(STAMP)
	mkdir -p out
	$(BIN)/sharedctl demo --scenario paper_convex --json out/demo.json

# Pure tests (simulations, codecs) on two workers; tests that start processes or open sockets
# (marked `processes`) one at a time afterwards, so their timing is not disturbed by the workers.
test: $(STAMP)
	$(BIN)/python -m pytest -n 2 --dist loadfile -m "not processes"
	$(BIN)/python -m pytest -m processes

paper: $(STAMP)
	$(BIN)/sharedctl paper --out docs/paper

clean:
	rm -rf $(VENV) build *.egg-info
