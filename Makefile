# The two commands a newcomer needs: `make demo` and `make test`.
# `make demo` installs the core package only (no extras) into .venv-demo; every other target
# installs everything the tests need into .venv. Each is created when missing and reinstalled
# when pyproject.toml is newer, so running both, in either order, leaves both correct.
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEMO_VENV  := .venv-demo
DEMO_BIN   := $(DEMO_VENV)/bin
DEMO_STAMP := $(DEMO_VENV)/.installed

.PHONY: install test test-fast demo bench lint docs docs-pictures clean slurm browser testmodels

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# The tests need every optional feature: datasets (TFDS, array-record, Grain, OpenCV), torch
# (PyPI's torch wheel brings its CUDA libraries: a fresh install of everything took 5.3 min and
# 7.5 GB), jax (the README's JAX snippet is run by the tests) and, through dev, the cluster and
# object-storage extras (Dask, fsspec, s3fs, moto's S3 server).
EXTRAS := dev,datasets,torch,jax,tf,hub

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[$(EXTRAS)]'
	touch $(STAMP)

install: $(STAMP)

# Two pytest-xdist workers (CI has 2 cores). loadgroup, not loadfile: a module whose tests share a
# module-scoped fixture (a render) stays on one worker (tests/conftest.py marks it), every other
# test is handed out alone, so a file of heavy independent tests (the benchmarks' smoke runs) is
# split across both workers instead of making the run's tail. PYTEST_WORKERS=0 runs serially.
PYTEST_WORKERS ?= 2
XDIST := -n $(PYTEST_WORKERS) --dist loadgroup

test: $(STAMP) browser testmodels
	$(BIN)/python -m pytest -q $(XDIST) --durations=40

browser:  # Debian's chromium + chromedriver for the `kubric view` browser tests (skipped when present)
	@if ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; then \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get update && $$SUDO apt-get install -y chromium chromium-driver; \
	fi

testmodels:  # Debian's assimp-testmodels: CMU BVH clips + skinned FBX/glTF files (character tests)
	@if [ ! -f /usr/share/assimp/models/BVH/01_01.bvh ]; then \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get update && $$SUDO apt-get install -y assimp-testmodels; \
	fi

# Everything but the tests marked `blender` (renders) or `slow` (servers, clusters, fault runs);
# bpy is blocked so a render test without the marker fails. `make test` runs them all.
test-fast: $(STAMP)
	@start=$$(date +%s); $(BIN)/python -m pytest -q $(XDIST) --no-blender -m "not slow"; rc=$$?; \
	echo "make test-fast: $$(( $$(date +%s) - start )) s wall"; exit $$rc

# The demo needs the core dependencies only (bpy, pybullet, numpy, ...): no torch, jax, Dask or
# TFDS. Editable, so the demo runs this checkout's code.
$(DEMO_BIN)/python:
	$(PYTHON) -m venv $(DEMO_VENV)
	$(DEMO_BIN)/python -m pip install --quiet --upgrade pip

$(DEMO_STAMP): pyproject.toml | $(DEMO_BIN)/python
	$(DEMO_BIN)/python -m pip install --quiet -e .
	touch $(DEMO_STAMP)

demo: $(DEMO_STAMP)
	$(DEMO_BIN)/python -m kubric.demo

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[$(EXTRAS),coacd,bench]'  # V-HACD vs CoACD, codecs vs libraries
	$(BIN)/python -m benchmarks

docs: $(STAMP)  # regenerate the generated pages, then build the HTML site into site/
	$(BIN)/python -m kubric.docgen
	$(BIN)/python -m pip install --quiet 'mkdocs>=1.6'
	$(BIN)/mkdocs build --strict --quiet

docs-pictures: $(STAMP)  # one small rendered picture per recipe for docs/recipes.md (a few CPU-minutes)
	$(BIN)/python -m kubric.docgen_pictures

slurm:  # Debian's Slurm, so that the single-node Slurm test runs instead of being skipped (root)
	apt-get install -y --no-install-recommends slurmctld slurmd slurm-client munge

lint: $(STAMP)
	$(BIN)/ruff check kubric tests

clean:
	rm -rf $(VENV) $(DEMO_VENV) build site *.egg-info
