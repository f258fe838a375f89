# `make serve` and `make test` each do all set-up on a fresh machine: `serve` installs the
# runtime only; `test` (and bench, soak, validation) adds the test and plot extras.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
SCENE  ?= railway

.PHONY: runtime install serve test soak robustness-soak bench validation clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

$(VENV)/.runtime: $(BIN)/python pyproject.toml
	$(BIN)/pip install --quiet -e .
	touch $@

$(VENV)/.installed: $(VENV)/.runtime
	$(BIN)/pip install --quiet -e '.[test,plot]'
	touch $@

runtime: $(VENV)/.runtime

install: $(VENV)/.installed

# make serve ARGS="--endpoint urg=tcp:127.0.0.1:0 --speed 2"
serve: runtime
	$(BIN)/lrf-emulator serve $(SCENE) $(ARGS)

test: install
	$(BIN)/python -m pytest -q

# An hour of the real daemon under everything at once (docs/performance.md, "Soak"); SOAK_MINUTES=N for less.
soak: install
	$(BIN)/lrf-emulator bench --section soak --minutes $${SOAK_MINUTES:-60}

# The robustness suite at length: every attack ROBUSTNESS_SCALE times longer (CI runs it at 1 in `make test`).
robustness-soak: install
	ROBUSTNESS_SCALE=$${ROBUSTNESS_SCALE:-10} $(BIN)/python -m pytest -q -m robustness

bench: install
	$(BIN)/lrf-emulator bench

validation: install
	$(BIN)/python -m emulator.validation docs/validation.md

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis
