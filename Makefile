# depthnav: `make demo` and `make test` work on a fresh machine with Python >= 3.11.
VENV    ?= .venv
PYTHON  ?= python3
PY      := $(VENV)/bin/python
STAMP   := $(VENV)/.installed
export MUJOCO_GL ?= egl
# Numba's on-disk JIT cache lives beside the sources; keep it per-checkout.
export NUMBA_CACHE_DIR ?= $(CURDIR)/.numba_cache

.PHONY: all demo test test-fast test-all bench lint assets clean

all: demo

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev]'
	@touch $(STAMP)

## The main job, headless: report, figures and a rerun recording in runs/demo/.
demo: $(STAMP)
	$(VENV)/bin/depthnav run scenarios/demo.toml --out runs/demo --rrd runs/demo/demo.rrd

## The test suite (unit, property and end-to-end scenario tests) on both cores.
test: $(STAMP)
	$(PY) -m pytest -n 2 -q

## Unit tests only (skips the slow end-to-end scenario tests).
test-fast: $(STAMP)
	$(PY) -m pytest -n 2 -q -m "not slow"

## Benchmarks: prints a table and writes bench/results.json.
bench: $(STAMP)
	$(PY) bench/run.py --out bench/results.json

lint: $(STAMP)
	$(VENV)/bin/ruff check sim autonomy tests bench

## Regenerate the shipped buildings in sim/assets from sim/blueprints.py.
assets: $(STAMP)
	$(PY) -m sim.simulator.blueprints

clean:
	rm -rf runs .pytest_cache .numba_cache
