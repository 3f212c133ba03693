# lineslam: `make demo` and `make test` work on a fresh machine with Python 3.11 and pip.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-dev
DATA ?= $(if $(LINESLAM_DATA),$(LINESLAM_DATA),../shared/datasets)
DEMO_LOG := datasets/sim/demo/log.clf
JOBS ?= 2

.PHONY: install demo test lint bench clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/lineslam slam $(DEMO_LOG) --out results/demo --plot
	$(BIN)/lineslam evaluate results/demo --relations datasets/sim/demo/relations.txt --ground-truth datasets/sim/demo/ground_truth.tum

test: $(STAMP)
	$(BIN)/python -m pytest -n $(JOBS) -q

lint: $(STAMP)
	$(BIN)/ruff check linefit slam tests scripts examples
	$(BIN)/ruff format --check linefit slam tests scripts examples
	$(BIN)/mypy

bench: $(STAMP)
	$(BIN)/python scripts/bench_extract.py
	$(BIN)/python scripts/bench_io.py
	$(BIN)/python scripts/bench_map.py
	$(BIN)/python scripts/bench_graph.py
	$(BIN)/python scripts/bench_slam.py
	$(BIN)/python scripts/bench_ekf.py

clean:
	rm -rf $(VENV) results .pytest_cache .mypy_cache .ruff_cache
