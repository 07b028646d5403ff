# `make run` and `make test` set up .venv on first use, then run or test.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install run test test-all test-browser acceptance lint nightly bench bench-full mutation clean

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

# every acceptance suite (the slow tests of one file) in a process of its own, two at a time,
# the quicker first;
# each writes results/acceptance/<suite>.json (figures, bounds, commit, date, machine, run time;
# tests/conftest.py). One suite: make acceptance SUITES=sizing
SUITES ?= collimation_acceptance reported_sigma superquantile stabilization_estimation \
	ground_independent blind_camera_acceptance diagnose_camera procedure_effects \
	stabilization_independent diagnose_stabilization nightly sizing stabilization_variants \
	collimation_procedure_acceptance collimation_independent discrepancy_acceptance \
	collimation_conventions noise_auto opencv_samples right_name_acceptance \
	large_data_acceptance \
	stabilization_null_acceptance
ACCEPTANCE_DIR ?= results/acceptance

acceptance: install
	@start=$$(date +%s); \
	$(MAKE) --no-print-directory -k -j2 $(SUITES:%=acceptance-%); status=$$?; \
	echo "make acceptance: $$(( $$(date +%s) - start )) s, results in $(ACCEPTANCE_DIR)/"; \
	exit $$status

acceptance-%: install
	@test -n "$(wildcard tests/test_$*.py tests/independent/test_$*.py)" || \
	(echo "no acceptance suite $*"; exit 2)
	@mkdir -p $(ACCEPTANCE_DIR)
	ACCEPTANCE_DIR=$(ACCEPTANCE_DIR) ACCEPTANCE_COMMAND="make acceptance SUITES=$*" \
	nice -n 5 $(BIN)/pytest -q -p no:cacheprovider -m slow -n 0 \
	$(firstword $(wildcard tests/test_$*.py tests/independent/test_$*.py)) \
	> $(ACCEPTANCE_DIR)/$*.log 2>&1 || (tail -5 $(ACCEPTANCE_DIR)/$*.log; exit 1)

# every shipped study's report.html and a diagnosis report in headless Chromium (Debian's
# chromium driven by Playwright; both installed here if missing): docs/validation/browser.md
CHROMIUM ?= /usr/bin/chromium
BROWSER_OUT ?= results/browser
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
test-browser: install
	test -x $(CHROMIUM) || { $(SUDO) apt-get update && $(SUDO) apt-get install -y chromium; }
	$(BIN)/python -c 'import playwright.sync_api' 2>/dev/null \
		|| $(BIN)/python -m pip install --quiet -e '.[browser]'
	CHROMIUM=$(CHROMIUM) MONTECARLO_BROWSER_OUT=$(BROWSER_OUT) \
		$(BIN)/pytest -m slow -n 0 -p no:cacheprovider -q -rs tests/test_browser.py

nightly: install
	$(BIN)/montecarlo nightly

bench: install
	$(BIN)/montecarlo bench --quick

bench-full: install
	$(BIN)/montecarlo bench --full

# one module or folder: make mutation MODULE=montecarlo/seed000/air.py (docs/validation/mutation.md)
mutation: install
	PYTHON_BIN=$(BIN)/python .ci/mutation $(MODULE)

lint: install
	$(BIN)/ruff check .
	$(BIN)/mypy

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis
