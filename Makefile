# The README's two commands are `make demo` and `make test`; the others are for development (CONTRIBUTING.md).
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
APT_PACKAGES := gir1.2-aravis-0.8 aravis-tools-cli libgirepository1.0-dev libcairo2-dev pkg-config chromium chromium-driver

.PHONY: demo test test-fast lint typecheck check venv system-deps

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,dev]"
	touch $@

venv: $(VENV)/.installed

system-deps:
	@if ! dpkg -s $(APT_PACKAGES) >/dev/null 2>&1; then \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(APT_PACKAGES); \
	fi

$(VENV)/.aravis: $(VENV)/.installed
	$(MAKE) system-deps
	$(PY) -m pip install --quiet "PyGObject<3.51"
	touch $@

demo: venv
	$(VENV)/bin/uwlab demo

# Everything in one session on four workers, two per core: the integration tests (processes, devices, ptys, GigE,
# Aravis, Chromium, Dask) spend much of their time waiting on restarts, timeouts and browsers, and the fits of the
# unit and slow tests fill those waits. A file is one work unit (its tests share simulators and fixtures), taken in
# the order given, so the longest files (tests/slow) start first and none of them starts last.
test: $(VENV)/.aravis
	$(PY) -m pytest -n 4 --dist loadfile --no-loadscope-reorder tests/slow tests/integration tests/unit uwlab

# The in-process unit tests and the doctests (no devices, no subprocesses), on two workers.
test-fast: venv
	$(PY) -m pytest -n 2 tests/unit uwlab

# ruff (rules and formatting) and the import-linter layer contracts of pyproject.toml.
lint: venv
	$(VENV)/bin/ruff check uwlab tests benchmarks
	$(VENV)/bin/ruff format --check uwlab tests benchmarks
	$(VENV)/bin/lint-imports

typecheck: venv
	$(VENV)/bin/mypy

check: lint typecheck test
