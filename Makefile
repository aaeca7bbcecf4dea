# depthnav: `make demo` and `make test` work on a fresh machine with Python >= 3.11.
VENV    ?= .venv
PYTHON  ?= python3
PY      := $(VENV)/bin/python
STAMP   := $(VENV)/.installed
WARM    := $(VENV)/.warm
RL      := $(VENV)/.rl
# PyTorch for the rl extra, installed first: a bare `torch` requirement can pull a CUDA
# build of several GB. Override, e.g. TORCH="torch --index-url https://download.pytorch.org/whl/cpu".
TORCH   ?= torch==2.13.0
export MUJOCO_GL ?= egl
# Numba's on-disk JIT cache lives beside the sources; keep it per-checkout.
export NUMBA_CACHE_DIR ?= $(CURDIR)/.numba_cache

.PHONY: all demo test test-fast test-all bench lint assets clean gl

all: demo

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev]'
	@touch $(STAMP)

## The rl extra (PyTorch, stable-baselines3, triton) for the policy-research tests and tools.
$(RL): $(STAMP)
	$(PY) -m pip install -q $(TORCH)
	$(PY) -m pip install -q -e '.[dev,rl]'
	@touch $(RL)

# The numba kernels compiled once after installing (about 40 s), so no run pays for it.
$(WARM): $(STAMP) | gl
	$(PY) -m sim.warmup
	@touch $(WARM)

## Mesa's EGL for headless depth rendering: installed if missing (root or sudo -n), else
## one line naming the command to run; then a GL context must open.
gl: $(STAMP)
	@bash scripts/setup_gl.sh
	@$(PY) -c "from mujoco import gl_context; gl_context.GLContext(8, 8).free()" 2>/dev/null || \
	  { echo "depthnav: no OpenGL context with MUJOCO_GL=$(MUJOCO_GL); install Mesa's EGL (scripts/setup_gl.sh lists the packages) or run with MUJOCO_GL=osmesa" >&2; exit 1; }

## The main job, headless: report, figures and a rerun recording in runs/demo/.
demo: $(STAMP) gl $(WARM)
	$(VENV)/bin/depthnav run scenarios/demo.toml --out runs/demo --rrd runs/demo/demo.rrd

## The test suite (unit, property and end-to-end scenario tests) on both cores.
test: $(STAMP) $(RL) gl $(WARM)
	DEPTHNAV_REQUIRE_GL=1 $(PY) -m pytest -n 2 -q

## Unit tests only (skips the slow end-to-end scenario tests).
test-fast: $(STAMP) $(RL) gl $(WARM)
	DEPTHNAV_REQUIRE_GL=1 $(PY) -m pytest -n 2 -q -m "not slow"

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
