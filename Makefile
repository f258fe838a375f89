# `make serve` and `make test` each do all set-up on a fresh machine.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
SCENE  ?= railway

.PHONY: install serve test soak bench validation lint clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.installed: $(BIN)/python pyproject.toml
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test,plot]'
	touch $@

install: $(VENV)/.installed

# make serve ARGS="--endpoint urg=tcp:127.0.0.1:0 --speed 2"
serve: install
	$(BIN)/lrf-emulator serve $(SCENE) $(ARGS)

test: install
	$(BIN)/python -m pytest -q

# The robustness suite at length: every attack ROBUSTNESS_SCALE times longer (CI runs it at 1 in `make test`).
soak: install
	ROBUSTNESS_SCALE=$${ROBUSTNESS_SCALE:-10} $(BIN)/python -m pytest -q -m robustness

bench: install
	$(BIN)/lrf-emulator bench

validation: install
	$(BIN)/python -m emulator.validation docs/validation.md

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis
