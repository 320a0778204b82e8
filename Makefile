# armsig — every target creates .venv and installs on first use; the install compiles the
# numerical kernels (`pipeline warmup`, ~25 s of CPU once) so the first `ik` answers at once.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
SESSION ?= robot3

.PHONY: install test lint bench bench-plan fuzz fuzz-import fuzz-inputs identify sessions clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test,lint]'
	$(BIN)/pipeline warmup
	touch $(STAMP)

install: $(STAMP)

# The suite runs on one pytest-xdist worker per core; an idle worker takes tests queued
# for the other (worksteal: 214 s against 248 s for whole files per worker, 2 cores, warm
# kernel cache). Serially: `make test PYTEST_ARGS=-n0`.
PYTEST_ARGS ?= -n auto --dist worksteal

test: $(STAMP)
	$(BIN)/pytest $(PYTEST_ARGS)

lint: $(STAMP)
	$(BIN)/ruff check pipeline armsig tests bench
	$(BIN)/ruff format --check pipeline armsig tests bench
	$(BIN)/mypy pipeline armsig
	$(BIN)/lint-imports --no-cache

# The peer comparison needs the optional `bench` extra (rtb); installed here when absent,
# and skipped by bench/peers.py with the reason when it cannot be installed.
bench: $(STAMP)
	$(BIN)/python -c "import roboticstoolbox" 2>/dev/null || $(BIN)/pip install --quiet -e '.[bench]' \
		|| echo "bench: could not install the bench extra; the peer comparison is skipped"
	$(BIN)/python -m bench

# Issue 28's simulated acceptance of `pipeline plan` (minutes): planned vs random pose sets
# and --target-rms-mm over 20 seeds, the information bound, the sweep plans' prediction.
bench-plan: $(STAMP)
	$(BIN)/python -m bench.plan_study
	$(BIN)/python -m bench.plan_study --bounds
	$(BIN)/python -m bench.plan_study --sweeps

# Issue 13's acceptance: 500 byte-level and 200 JSON-level seeded mutations of robot3's recording.
fuzz: $(STAMP)
	$(BIN)/python tests/fuzz_recording.py sessions/robot3/recording.mcap --byte 500 --json 200

# Issue 32: 1,000 seeded import, map, validate, export, ik --out and fault cases, and 20
# concurrent runs (tests/fuzz_import.py; 213 s on 2 cores).
fuzz-import: $(STAMP)
	$(BIN)/python tests/fuzz_import.py --cases 1000 --concurrent 20

# Issue 44: 1,000 seeded odd values on plan, map (convention, sigma), validate --against,
# session NAMEs and export --onto (tests/fuzz_inputs.py; 132 s on 2 cores).
fuzz-inputs: $(STAMP)
	$(BIN)/python tests/fuzz_inputs.py --cases 1000

# The seven committed sessions: seeds 1-7, every other option at its default.
sessions: $(STAMP)
	for i in 1 2 3 4 5 6 7; do $(BIN)/pipeline simulate robot$$i --seed $$i --force || exit 1; done

identify: $(STAMP)
	$(BIN)/pipeline identify sessions/$(SESSION)

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache .hypothesis build dist *.egg-info
	rm -rf sessions/*/stages sessions/*/report sessions/*/export sessions/*/viz.mcap
