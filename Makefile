# `make run`: a default swarm to consensus.
# `make test`: lint, the C robot's unit tests, then the whole test suite (every tier) on
#   TEST_WORKERS workers (pytest-xdist; three on two cores, as its live runs mostly wait
#   on each other: about 7.5 minutes of pytest against 9 with two), printing
#   the 20 slowest tests. CI's budget for it: 10 minutes on 2 cores.
# `make test-fast`: the fast tier only: the tests of the pure layers, which start no process
#   and open no Zenoh session or network connection. The tier is set per test in
#   tests/tiers.py; tests/test_tiers.py fails if a test module is in no tier, and
#   tests/conftest.py fails a fast test that starts a process, connects, listens or sends
#   on a socket, or opens a Zenoh session.
# `make check-published`: every published Section 5 run again (all 600 of
#   docs/section5-runs.json, `swarm section5 --check`; about 7 minutes of both cores), the
#   tables of docs/section5.md and the data of Figures 4 and 5 made from them; then the
#   tests that run published runs again (tests/tiers.py PUBLISHED: `pytest --published`):
#   a sample of every study's runs, one of each kind, drawn from CHECK_SEED (`swarm study
#   NAME --check --sample-seed S`, docs/studies.md).
#   CI runs it after `make test`. docs/testing.md says what is published from runs but
#   not run again by any check.
# `make check-portable`: a sample of the published runs again on emulated CPUs (qemu-user:
#   x86-64 without AVX-512, x86-64-v2 without AVX, aarch64) against this machine's runs
#   and the published files, and the C robot cross-built for aarch64: its unit tests and
#   a lockstep run under qemu-aarch64 (portable/check.py; `.venv/bin/python -m portable
#   --help` for a larger sample). As root it installs qemu-user and the aarch64 cross
#   compiler when they are missing; what it downloads is kept in .portable/. CI runs it
#   after `make check-published`.
# `make check-mcu`: the robot in C as Cortex-M4F firmware under qemu-system-arm
#   (portable/mcu.py): its RAM and flash against their budgets, its unit tests on
#   mps2-an386, a build without entropy refusing to start, and lockstep runs with it as
#   robot 9 on netduinoplus2 over a serial line (seeds 0 and 3, and 7 and 8 with camera
#   noise) against the all-emulated runs. Without arm-none-eabi-gcc and newlib,
#   qemu-system-arm or socat it says what is missing and skips (exit 0). CI runs it after
#   `make check-portable`, installing Debian's packages for it as root.
# All of them create .venv and install the project on first use (and again when the
# lock changes): the exact versions and hashes of requirements/run.lock (make run) or
# requirements/test.lock (the rest), then the project itself without dependencies (and for
# the tests the example plug-in, examples/linear_pool, which the suite runs too).
# `make lock` writes both locks again from pyproject.toml's ranges (docs/testing.md says
# when, and that published numbers are made again after).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
RUN_LOCK := requirements/run.lock
TEST_LOCK := requirements/test.lock
UV_VERSION := 0.13.9
LOCK_OPTIONS := --generate-hashes --universal --fork-strategy fewest --python-version 3.11
TEST_WORKERS ?= 3
# The seed of the studies' sample in make check-published: the day's date, so each day's
# check makes other runs (make check-published CHECK_SEED=20250314 draws that day's again).
CHECK_SEED ?= $(shell date -u +%Y%m%d)

.PHONY: run test c-robot-test test-fast check-published check-portable check-mcu explore lint bench lock c-robot clean cores clean-cores

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: $(RUN_LOCK) pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet --require-hashes -r $(RUN_LOCK)
	$(BIN)/python -m pip install --quiet --no-deps -e .
	touch $@

$(VENV)/.installed-test: $(TEST_LOCK) pyproject.toml examples/linear_pool/pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet --require-hashes -r $(TEST_LOCK)
	$(BIN)/python -m pip install --quiet --no-deps -e .
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e examples/linear_pool
	touch $@ $(VENV)/.installed

run: $(VENV)/.installed
	$(BIN)/python -m bestofn_swarm.plumbing.cores build
	$(BIN)/swarm run

# The cores' build (a minute of one core on a fresh clone) runs beside the lint and the C
# robot's tests; the suite starts when both are done.
test: $(VENV)/.installed-test
	$(BIN)/python -m bestofn_swarm.plumbing.cores build & cores=$$!; \
	$(MAKE) --no-print-directory lint c-robot-test; checks=$$?; \
	wait $$cores && exit $$checks
	$(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile --durations=20

c-robot-test:
	@if command -v $${CC:-gcc} >/dev/null 2>&1; then $(MAKE) -C c_robot test; \
	else echo "make test: no C compiler ($${CC:-gcc}): the C robot's unit tests are skipped"; fi

# The compiled cores (bestofn_swarm/plumbing/cores.py): mypyc builds the pure modules of the tick in
# place, again whenever one of them changes; without a C compiler or mypyc, make says so
# and the source runs. `make clean-cores` removes them.
cores: $(VENV)/.installed
	$(BIN)/python -m bestofn_swarm.plumbing.cores build

clean-cores:
	@if [ -x $(BIN)/python ]; then $(BIN)/python -m bestofn_swarm.plumbing.cores clean; fi

# The robot in C (c_robot/build/c-robot): gcc or cc, and make.
c-robot:
	$(MAKE) -C c_robot

test-fast: $(VENV)/.installed-test
	$(BIN)/python -m bestofn_swarm.plumbing.cores build
	$(BIN)/python -m pytest -m fast

check-published: $(VENV)/.installed-test
	$(BIN)/python -m bestofn_swarm.plumbing.cores build
	$(BIN)/swarm section5 --check
	STUDY_CHECK_SEED=$(CHECK_SEED) $(BIN)/python -m pytest --published --durations=20

check-portable: $(VENV)/.installed-test
	$(BIN)/python -m bestofn_swarm.plumbing.cores build
	$(BIN)/python -m portable

check-mcu: $(VENV)/.installed-test
	$(BIN)/python -m bestofn_swarm.plumbing.cores build
	$(BIN)/python -m portable.mcu

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

lock: | $(BIN)/python
	$(BIN)/python -m pip install --quiet uv==$(UV_VERSION)
	$(BIN)/uv pip compile pyproject.toml --extra cores $(LOCK_OPTIONS) -o $(RUN_LOCK)
	$(BIN)/uv pip compile pyproject.toml --extra test --extra cores $(LOCK_OPTIONS) -o $(TEST_LOCK)

clean: clean-cores
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache .mypy_cache .portable
	$(MAKE) -C c_robot clean
