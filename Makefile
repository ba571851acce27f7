# Two commands do all set-up on a fresh clone:
#   make demo   -- creates .venv if missing, installs, runs the demo
#   make test   -- creates .venv if missing, installs, runs ruff and pytest
# The virtual environment is built once and reused; it is rebuilt when pyproject.toml changes.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: venv demo test bench docs clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/sustain-drake demo

test: $(STAMP)
	$(VENV)/bin/ruff check sustain_drake tests bench
	$(PY) -m pytest -q

bench: $(STAMP)
	$(PY) bench/bench_identifier.py

# Regenerates docs/scenarios.md from the scenario dataclasses' field comments.
docs: $(STAMP)
	$(PY) -m sustain_drake.station.reference

clean:
	rm -rf $(VENV) build *.egg-info
