# Every target calls the tools configured in pyproject.toml; `make test` is what CI runs.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup demo test lint bench view clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[dev]"
	touch $(STAMP)

setup: $(STAMP)

## The main job on the bundled cell: check the taught poses, plan every route.
demo: $(STAMP)
	$(BIN)/safepath check scenes/quality_check_cell
	$(BIN)/safepath plan scenes/quality_check_cell --out out/quality_check_cell

## Lint, type-check and run the whole test suite.
test: $(STAMP)
	$(BIN)/ruff check safepath tests benchmarks examples
	$(BIN)/mypy safepath
	$(BIN)/pytest -q

bench: $(STAMP)
	$(BIN)/python benchmarks/collision_checks.py

view: $(STAMP)
	$(BIN)/safepath view scenes/quality_check_cell

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache
