# The README's two commands are `make demo` and `make test`; the others are for development (CONTRIBUTING.md).
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
APT_PACKAGES := gir1.2-aravis-0.8 aravis-tools-cli libgirepository1.0-dev libcairo2-dev pkg-config chromium chromium-driver

UV_VERSION := 0.13.9
# uv, pinned, in a venv of its own (only python3.11 and pip are needed to start); it installs .venv from uv.lock.
TOOLS := .tools
UV := $(TOOLS)/bin/uv
UV_STAMP := $(TOOLS)/.uv-$(UV_VERSION)
# Exactly the locked versions (--frozen: uv.lock as committed, never re-resolved, each file checked against its
# hash), uwlab itself editable; the interpreter is $(PYTHON), never one uv would download.
export UV_PYTHON_DOWNLOADS := never
# Bytecode compiled at install, as pip does and uv does not by default: where PYTHONDONTWRITEBYTECODE is set (as in
# many containers) Python would otherwise compile every module it imports from source, in every process (the demo's
# imports took 8–9 s instead of 3). uwlab's own modules, editable, are compiled before each run (COMPILE).
export UV_COMPILE_BYTECODE := 1
SYNC := $(UV) sync --frozen --python $(PYTHON)

.PHONY: demo test test-fast lint typecheck check venv system-deps lock-check

$(UV_STAMP):
	$(PYTHON) -m venv $(TOOLS)
	$(TOOLS)/bin/python -m pip install --quiet "uv==$(UV_VERSION)"
	touch $@

# What the demo needs and nothing more: uwlab's own dependencies. --inexact: a .venv made by `make venv` or
# `make test` keeps its tools.
$(VENV)/.demo: pyproject.toml uv.lock | $(UV_STAMP)
	$(SYNC) --inexact
	touch $@

# Everything but the Aravis bindings: the test and dev extras.
$(VENV)/.installed: pyproject.toml uv.lock | $(UV_STAMP)
	$(SYNC) --extra test --extra dev
	touch $@

venv: $(VENV)/.installed

# CI fails when uv.lock no longer matches pyproject.toml (CONTRIBUTING.md: "Dependencies and the lock").
lock-check: | $(UV_STAMP)
	$(UV) lock --check

system-deps:
	@if ! dpkg -s $(APT_PACKAGES) >/dev/null 2>&1; then \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(APT_PACKAGES); \
	fi

# PyGObject builds against Debian's GObject introspection and cairo headers (system-deps).
$(VENV)/.aravis: $(VENV)/.installed
	$(MAKE) system-deps
	$(SYNC) --extra test --extra dev --extra aravis
	touch $@

COMPILE = $(VENV)/bin/python -m compileall -q uwlab

demo: $(VENV)/.demo
	$(COMPILE)
	$(VENV)/bin/uwlab demo

# Everything in one session on four workers, two per core: the integration tests (processes, devices, ptys, GigE,
# Aravis, Chromium, Dask) spend much of their time waiting on restarts, timeouts and browsers, and the fits of the
# unit and slow tests fill those waits. A file is one work unit (its tests share simulators and fixtures), taken in
# the order given, so the longest files (tests/slow) start first and none of them starts last.
test: $(VENV)/.aravis
	$(COMPILE)
	$(PY) -m pytest -n 4 --dist loadfile --no-loadscope-reorder --durations=15 tests/slow tests/integration tests/unit uwlab

# The in-process unit tests and the doctests (no devices, no subprocesses), on two workers.
test-fast: venv
	$(COMPILE)
	$(PY) -m pytest -n 2 tests/unit uwlab

# ruff (rules and formatting) and the import-linter layer contracts of pyproject.toml.
lint: venv
	$(VENV)/bin/ruff check uwlab tests benchmarks
	$(VENV)/bin/ruff format --check uwlab tests benchmarks
	$(VENV)/bin/lint-imports

typecheck: venv
	$(VENV)/bin/mypy

check: lock-check lint typecheck test
