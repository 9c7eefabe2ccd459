PY ?= python3.11
VENV ?= .venv
BIN := $(VENV)/bin
export MPLBACKEND := Agg

.PHONY: setup test lint format tables reproduce bench ci

$(BIN)/python:
	$(PY) -m venv $(VENV)

setup: $(BIN)/python
	# torch first and pinned: an unpinned torch would pull a multi-GB CUDA build
	$(BIN)/pip install -q -c constraints.txt torch==2.13.0
	$(BIN)/pip install -q -c constraints.txt -e ".[dev,ray]"

test:
	$(BIN)/python -m pytest -q

lint:
	$(BIN)/ruff check distgprl tests scripts benchmarks
	$(BIN)/ruff format --check distgprl tests scripts benchmarks

format:
	$(BIN)/ruff check --fix distgprl tests scripts benchmarks
	$(BIN)/ruff format distgprl tests scripts benchmarks

tables:
	$(BIN)/distgprl tables --preset paper
	$(BIN)/distgprl curves --preset paper

reproduce:
	$(BIN)/distgprl sweep --preset paper
	$(MAKE) tables

bench:
	$(BIN)/distgprl bench
