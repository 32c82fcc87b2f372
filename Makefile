# Slipstream: `make demo` runs the league on embedded defaults, `make test` runs the tests.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# The CPU build of PyTorch; pip finds the wheel on disk on the project's machines.
TORCH_SPEC ?= torch==2.13.0

.PHONY: install demo test lint bench clean

install: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet "$(TORCH_SPEC)"
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

demo: install
	$(BIN)/slipstream demo

lint: install
	$(BIN)/ruff check .

# The suite on every core (pytest-xdist), a test file per process: a file's tests share
# its server and database. `make test TEST_WORKERS=0` runs it in one process. A worker that
# crashes or hangs (see the timeouts in pyproject.toml) ends the run instead of being
# replaced: a replacement would run the crashed test again.
TEST_WORKERS ?= auto

test: install lint
	$(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile --max-worker-restart 0

# The quick benchmarks, each under about 30 s on a 2-core machine; each prints its table and
# appends it to benchmarks/results/ (`make bench BENCH_ARGS=--no-record` only prints).
# Left out: hostile_uploads (over a minute, 40 x 16 MB uploads at once), api_load (needs
# wrk; about 2 minutes), league_throughput without --quick (minutes), and the training
# ones, race_quality, time_to_lap and train_profile (minutes to hours each).
bench: install
	$(BIN)/python benchmarks/camera_frame.py $(BENCH_ARGS)
	$(BIN)/python benchmarks/env_throughput.py $(BENCH_ARGS)
	$(BIN)/python benchmarks/submission_io.py $(BENCH_ARGS)
	$(BIN)/python benchmarks/sandbox.py $(BENCH_ARGS)
	$(BIN)/python benchmarks/body_flood.py $(BENCH_ARGS)
	$(BIN)/python benchmarks/pursuit_races.py $(BENCH_ARGS)
	$(BIN)/python benchmarks/league_throughput.py --quick $(BENCH_ARGS)

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis *.egg-info
