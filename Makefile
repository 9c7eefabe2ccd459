PY ?= python3.11
VENV ?= .venv
BIN := $(VENV)/bin
export MPLBACKEND := Agg

.PHONY: setup test test-cluster lint format docs tables notebook reproduce bench ci

$(BIN)/python:
	$(PY) -m venv $(VENV)

# Where torch comes from: empty = the configured pip index. Plain PyPI serves the CUDA build
# on Linux; set TORCH_INDEX=https://download.pytorch.org/whl/cpu there for the CPU build.
TORCH_INDEX ?=

setup: $(BIN)/python
	# torch first and pinned: an unpinned torch would pull a multi-GB CUDA build
	$(BIN)/pip install -q -c constraints.txt $(if $(TORCH_INDEX),--index-url $(TORCH_INDEX)) torch==2.13.0
	$(BIN)/pip install -q -c constraints.txt -e ".[dev,ray,docs]"

# Tests run on TEST_WORKERS processes (pytest-xdist), each test file whole on one worker so a
# file's module-scoped fixtures are built once; TEST_WORKERS=0 runs them in this process.
TEST_WORKERS ?= 2

test:
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile

# The sweep on a two-node Ray cluster on this machine (issue 52): a worker node killed, a worker
# node frozen, then the head killed mid-sweep, re-runs, a local sweep of the same runs,
# compared; prints the counts (complete / lost / resumed / duplicated / corrupt) and fails on
# any. About 4 to 5 min on 2 cores.
test-cluster:
	$(BIN)/python scripts/cluster_test.py

# mypy: its files and settings are pyproject.toml's [tool.mypy] (strict on the numerics core)
lint:
	$(BIN)/ruff check distgprl tests scripts benchmarks
	$(BIN)/ruff format --check distgprl tests scripts benchmarks
	$(BIN)/mypy

# The documentation site into site/ (mkdocs.yml; docs/ and the pages scripts/docs_pages.py
# generates from the package, paper_figures/ and CHANGELOG.md); --strict: a broken link or
# reference, or any other warning, fails the build. `$(BIN)/mkdocs serve` to browse it.
docs:
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

format:
	$(BIN)/ruff check --fix distgprl tests scripts benchmarks
	$(BIN)/ruff format distgprl tests scripts benchmarks

tables:
	$(BIN)/distgprl tables --preset paper
	$(BIN)/distgprl curves --preset paper
	$(BIN)/distgprl mechanisms --preset paper
	$(BIN)/python scripts/readme_results.py
	$(MAKE) notebook

# The Python-API notebook's stored outputs read the committed results: re-run it in place
# (cell metadata but its tags cleared, so a refresh changes only what the results change)
notebook:
	MPLBACKEND=Agg $(BIN)/jupyter nbconvert --to notebook --execute --inplace \
	  --ClearMetadataPreprocessor.enabled=True --ClearMetadataPreprocessor.preserve_cell_metadata_mask=tags \
	  docs/guides/python-api-notebook.ipynb


reproduce:
	$(BIN)/distgprl sweep --preset paper
	$(MAKE) tables

bench:
	$(BIN)/distgprl bench
