# Two commands on a fresh machine: `make demo` and `make test` (SPEC §1).
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
PIP    := $(BIN)/python -m pip --disable-pip-version-check -q
export JSBSIM_DEBUG := 0
export RAY_USAGE_STATS_ENABLED := 0
export MPLBACKEND := Agg

.PHONY: venv demo test test-slow lint bench clean
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

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/lint-imports

bench: $(STAMP)
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) build dist *.egg-info .pytest_cache .ruff_cache
