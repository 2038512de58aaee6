# Two commands on a fresh machine: `make demo` and `make test` (README, "Quick start").
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
PIP    := $(BIN)/python -m pip --disable-pip-version-check -q
export JSBSIM_DEBUG := 0
export RAY_USAGE_STATS_ENABLED := 0
export MPLBACKEND := Agg

.PHONY: venv demo test test-slow test-bluesky lint bench bench-performance bench-studies clean
venv: $(STAMP)

# The constraints file pins torch to the CPU wheel (torch==2.13.0) for our own installs.
$(STAMP): pyproject.toml constraints.txt
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(PIP) install -c constraints.txt -e '.[test,gcs]' 2> $(VENV)/pip-warnings.log || \
		{ cat $(VENV)/pip-warnings.log; exit 1; }
	@touch $@

demo: $(STAMP)
	$(BIN)/uavxai run scenarios/demo.yaml --out runs/demo --force

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -q

# Statistical experiments and long training runs (minutes to hours); not part of `make test`.
test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow

# The mvp planner against BlueSky's own MVP (tests/test_avoidance_mvp.py -k bluesky). BlueSky
# needs numpy below 2.4, so it gets a small venv of its own; uavxai is read from the tree.
BLUESKY := .venv-bluesky
test-bluesky:
	@test -x $(BLUESKY)/bin/python || $(PYTHON) -m venv $(BLUESKY)
	$(BLUESKY)/bin/python -m pip --disable-pip-version-check -q install \
		-r tests/requirements-bluesky.txt 2> $(BLUESKY)/pip-warnings.log || \
		{ cat $(BLUESKY)/pip-warnings.log; exit 1; }
	UAVXAI_BLUESKY=1 PYTHONPATH=$(CURDIR) $(BLUESKY)/bin/python -m pytest -q -p no:cacheprovider \
		tests/test_avoidance_mvp.py -k bluesky

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/lint-imports

# Speed against a baseline run in the same process (minutes), then the studies: what a method
# buys in quality or safety (some fly campaigns for hours; see each script's --help).
bench: bench-performance bench-studies

bench-performance: $(STAMP)
	@for b in benchmarks/performance/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

bench-studies: $(STAMP)
	@for b in benchmarks/studies/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) $(BLUESKY) build dist *.egg-info .pytest_cache .ruff_cache
