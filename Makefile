# `make serve` and `make test` each do all set-up on a fresh machine.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
SCENE  ?= railway

.PHONY: install serve test bench validation lint clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.installed: $(BIN)/python pyproject.toml
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[test,plot]'
	touch $@

install: $(VENV)/.installed

serve: install
	$(BIN)/lrf-emulator serve $(SCENE)

test: install
	$(BIN)/python -m pytest -q

bench: install
	$(BIN)/lrf-emulator bench

validation: install
	$(BIN)/python -m emulator.validation docs/validation.md

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis
