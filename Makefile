# User entry points. Every target does its own set-up first (scripts/bootstrap.sh, idempotent).
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python

.PHONY: setup demo test lint format bench clean

setup:
	@./scripts/bootstrap.sh

demo: setup  ## the main job
	@if [ -x $(VENV)/bin/friction-demo ]; then $(VENV)/bin/friction-demo $(ARGS); else $(VENV)/bin/friction-doctor; fi

test: setup  ## the full test suite (lint + pytest in parallel workers, see scripts/run-tests.sh; ARGS go to pytest)
	@./scripts/run-tests.sh $(ARGS)

lint: setup
	@$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check .

format: setup
	@$(VENV)/bin/ruff check --fix . ; $(VENV)/bin/ruff format .

bench: setup  ## every benchmark; figures to bench/results/*.json
	@./scripts/run-benchmarks.sh $(ARGS)

clean:
	rm -rf build install log .pytest_cache
