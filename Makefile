# The two commands of the README: `make demo` and `make test`.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
APT_PACKAGES := gir1.2-aravis-0.8 aravis-tools-cli libgirepository1.0-dev libcairo2-dev pkg-config chromium chromium-driver

.PHONY: demo test venv system-deps

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
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

test: $(VENV)/.aravis
	$(VENV)/bin/python -m pytest
