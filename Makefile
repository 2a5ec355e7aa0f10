# `make run`: a default swarm to consensus.
# `make test`: lint, then the whole test suite (every tier; CI's budget for it: 15 minutes
#   on 2 cores). tests/test_section5.py reruns only seeds 0-9 of Section 5.
# `make test-fast`: the fast tier only: the tests of the pure layers, which start no process
#   and open no Zenoh session or network connection (about 950 tests, 100 s wall on a quiet
#   2-core machine; more when it is shared). The tier is FAST in tests/tiers.py, less the
#   whole-swarm tests in SLOW; tests/test_tiers.py fails if a test module is in no tier,
#   and tests/conftest.py fails a fast test that starts a process, connects, listens or
#   sends on a socket, or opens a Zenoh session.
# `make check-published`: every published Section 5 run again (all 600 of
#   docs/section5-runs.json, `swarm section5 --check`; about 7 minutes of both cores), and
#   the tables of docs/section5.md and the data of Figures 4 and 5 made from them. CI
#   runs it after `make test`. Published from runs but NOT rerun by any check: the PNGs
#   (drawn from the checked data); docs/section5.md's lag and settings-study blocks and
#   docs/section5-lag.json (benchmarks/section5_study.py, section5_lag.py);
#   docs/scale-runs.json but 3 of its 48 runs (tests/test_scale_doc.py reruns in process
#   10 robots seeds 0 and 7, 50 robots seed 3, and renders docs/scale.md from the file);
#   docs/byzantine.md, docs/robustness.md (each says the commit it was made at),
#   docs/wellstirred.md's Figure 1 table, and docs/performance.md (timings).
#   docs/testing.md says the same.
# All of them create .venv and install the project on first use (and again when
# pyproject.toml changes).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: run test test-fast check-published explore lint bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@ $(VENV)/.installed

run: $(VENV)/.installed
	$(BIN)/swarm run

test: $(VENV)/.installed-test
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy
	$(BIN)/python -m pytest

test-fast: $(VENV)/.installed-test
	$(BIN)/python -m pytest -m fast

check-published: $(VENV)/.installed
	$(BIN)/swarm section5 --check

# The property tests with fresh random examples (make test repeats the same ones).
explore: $(VENV)/.installed-test
	HYPOTHESIS_PROFILE=explore $(BIN)/python -m pytest tests/test_decision.py \
		tests/test_pooling.py tests/test_fuzz.py tests/test_vectors.py tests/test_camera_vision.py

lint: $(VENV)/.installed-test
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

bench: $(VENV)/.installed-test
	$(BIN)/python benchmarks/wellstirred.py
	$(BIN)/python benchmarks/swarm_speed.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache .mypy_cache
