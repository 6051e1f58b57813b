# The two commands a newcomer needs: `make demo` and `make test`.
# Every target creates .venv (python3.11) and installs the project when missing or stale.
PYTHON ?= python3.11
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: install test test-fast demo bench lint docs clean slurm browser testmodels

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# The tests need every optional feature: datasets (TFDS, array-record, Grain, OpenCV), torch
# (PyPI's torch wheel brings its CUDA libraries: a fresh install of everything took 5.3 min and
# 7.5 GB), jax (the README's JAX snippet is run by the tests) and, through dev, the cluster and
# object-storage extras (Dask, fsspec, s3fs, moto's S3 server).
EXTRAS := dev,datasets,torch,jax

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[$(EXTRAS)]'
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP) browser testmodels
	$(BIN)/python -m pytest -q

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
	@start=$$(date +%s); $(BIN)/python -m pytest -q --no-blender -m "not slow"; rc=$$?; \
	echo "make test-fast: $$(( $$(date +%s) - start )) s wall"; exit $$rc

demo: $(STAMP)
	$(BIN)/python -m kubric.demo

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[$(EXTRAS),coacd,bench]'  # V-HACD vs CoACD, codecs vs libraries
	$(BIN)/python -m benchmarks

docs: $(STAMP)  # regenerate the generated pages, then build the HTML site into site/
	$(BIN)/python -m kubric.docgen
	$(BIN)/python -m pip install --quiet 'mkdocs>=1.6'
	$(BIN)/mkdocs build --strict --quiet

slurm:  # Debian's Slurm, so that the single-node Slurm test runs instead of being skipped (root)
	apt-get install -y --no-install-recommends slurmctld slurmd slurm-client munge

lint: $(STAMP)
	$(BIN)/ruff check kubric tests

clean:
	rm -rf $(VENV) build site *.egg-info
