# `make run` and `make test` set up .venv on first use, then run or test.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install run test test-all lint nightly bench bench-full mutation clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,camera]'
	touch $(STAMP)

install: $(STAMP)

run: install
	$(BIN)/montecarlo run studies/table1.toml

# the default tests in one process per core, each test file kept in one process
test: install lint
	$(BIN)/pytest -m "not slow" -n auto --dist loadfile

test-all: install lint
	$(BIN)/pytest

nightly: install
	$(BIN)/montecarlo nightly

bench: install
	$(BIN)/montecarlo bench --quick

bench-full: install
	$(BIN)/montecarlo bench --full

# one module or folder: make mutation MODULE=montecarlo/seed000/air.py (docs/testing.md)
mutation: install
	PYTHON_BIN=$(BIN)/python .ci/mutation $(MODULE)

lint: install
	$(BIN)/ruff check .
	$(BIN)/mypy

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis
