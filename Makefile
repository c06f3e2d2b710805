# Developer entry points. `make test` is what CI runs (see .ci/run).

SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
STAMP := $(VENV)/.installed
# Debian's chromium package installs here (the `chromium` target checks it).
CHROMIUM ?= /usr/bin/chromium
# sudo only when not already root
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: venv explore test chromium bench clean

venv: $(STAMP)

# Re-install only when pyproject.toml changes (or the venv is missing).
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/python -m pip install --upgrade pip
	$(VENV)/bin/python -m pip install -e '.[test]'
	touch $@

# With no arguments laav-explore opens its bundled demo sequence.
explore: venv
	$(VENV)/bin/laav-explore

# Headless Chromium for the browser tests; installed from Debian only when missing.
chromium:
	@if [ -x $(CHROMIUM) ]; then \
	  echo "chromium: $$($(CHROMIUM) --version 2>/dev/null || echo present)"; \
	else \
	  $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get update && \
	  $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y chromium; \
	fi

test: venv chromium
	$(VENV)/bin/ruff check .
	$(VENV)/bin/python -m pytest -q

# The paper's table and figures on Hopkins155 (set HOPKINS155 to its folder).
HOPKINS155 ?= ../shared/data/hopkins155
bench: venv
	$(VENV)/bin/laav bench --data $(HOPKINS155) --methods laav,rv --seeds 5 --noise 0,0.5,1,2 --out bench-out
	$(VENV)/bin/python benchmarks/speed.py --data $(HOPKINS155)

clean:
	rm -rf $(VENV) build dist *.egg-info .pytest_cache .ruff_cache .hypothesis
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
