# Every target calls the tools configured in pyproject.toml; `make test` is what CI runs.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup kernels browser demo test lint docs bench bench-peers view clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[dev]"
	touch $(STAMP)

setup: $(STAMP) kernels

## The numba kernels compiled ahead of time into the venv's cache, .venv/var/cache/safepath
## (30-95 s; nothing to do when the build of the current sources exists), and the bundled
## cells' robot parts made there. If it fails, numba's JIT compiles them on first use
## (tests/test_aot.py then fails, saying why). Then safepath's own Python
## bytecode (an editable install has none, and a process started with
## PYTHONDONTWRITEBYTECODE set never writes it: each would compile every module it
## imports, ~0.15 s a process).
kernels: $(STAMP)
	$(BIN)/safepath build-kernels || echo "kernels not compiled ahead of time: numba's JIT will compile them"
	$(BIN)/python -m compileall -q safepath

## Debian's Chromium for the browser test of the review session (needs root).
browser:
	@command -v chromium >/dev/null 2>&1 || { \
	  echo "installing Debian's chromium for the browser test"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; }

## The main job on the bundled cell: check the taught poses, plan every route.
demo: $(STAMP) kernels
	$(BIN)/safepath check scenes/quality_check_cell
	$(BIN)/safepath plan scenes/quality_check_cell --out out/quality_check_cell

RUFF := $(BIN)/ruff check safepath tests benchmarks examples docs
MYPY := $(BIN)/mypy safepath

lint: $(STAMP)
	$(RUFF)
	$(MYPY)

## The HTML API reference from the docstrings (pdoc) into out/api/ (open out/api/index.html);
## a warning of pdoc's, or a cross-reference to a safepath name that names nothing, fails it.
docs: $(STAMP)
	$(BIN)/python docs/build_api.py out/api

## Lint, type-check and run the project's tests, then print the wall time they took.
## (The peers' smoke test, which installs their venvs, runs only in `make bench-peers`.)
test: $(STAMP) kernels browser
	@start=$$(date +%s); status=0; \
	{ $(RUFF) && $(MYPY) && $(BIN)/pytest -q; } || status=$$?; \
	echo "make test: lint, type check and tests took $$(( $$(date +%s) - start )) s wall"; \
	exit $$status

## Speed figures (each script prints its own; --save writes benchmarks/results/*.json and
## the table benchmarks/results/FIGURES.md the README links).
bench: $(STAMP) kernels
	$(BIN)/python benchmarks/collision_checks.py --save
	$(BIN)/python benchmarks/plan_cycle.py --save
	$(BIN)/python benchmarks/panda_set.py --save
	$(BIN)/python benchmarks/runtime_heartbeat.py --save
	$(BIN)/python benchmarks/runtime_recovery.py
	$(BIN)/python benchmarks/cold_start.py --save

## Side-by-side run against mplib, pyroboplan, roboplan (creates their own venvs, ~2 GB
## under benchmarks/results/envs), after its smoke test.
bench-peers: $(STAMP)
	SAFEPATH_PEERS_SMOKE=1 $(BIN)/pytest -q tests/test_peers_smoke.py
	$(BIN)/python benchmarks/peers/run.py

view: $(STAMP)
	$(BIN)/safepath view scenes/quality_check_cell

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache
