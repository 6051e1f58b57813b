# The two commands a newcomer needs: `make demo` and `make test`.
# Every target creates .venv (python3.11) and installs the project when missing or stale.
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: install test demo bench lint clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# The tests need every optional feature: datasets (TFDS, array-record, Grain, OpenCV), torch
# (PyPI's torch wheel brings its CUDA libraries: a fresh install of everything took 5.3 min and
# 7.5 GB) and
# jax (the README's JAX snippet is run by the tests).
EXTRAS := dev,datasets,torch,jax

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[$(EXTRAS)]'
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -q

demo: $(STAMP)
	$(BIN)/python -m kubric.demo

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[$(EXTRAS),coacd]'  # bench_assets compares V-HACD with CoACD
	$(BIN)/python -m benchmarks

lint: $(STAMP)
	$(BIN)/ruff check kubric tests

clean:
	rm -rf $(VENV) build *.egg-info
