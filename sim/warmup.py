"""Compile the numba kernels of a run once, into numba's on-disk cache, so that the first
real run starts at once.

Numba compiles each kernel on its first call (about 40 s for a run's kernels on a 2-core
machine) and, with ``cache=True``, keeps the machine code on disk (``NUMBA_CACHE_DIR``;
the Makefile puts it in ``.numba_cache`` of the checkout). ``make`` runs this after
installing, so the cost is paid by the installation, not by the first ``make demo``.
``depthnav warmup`` does the same after a plain ``pip install``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path


def warm_up(verbose: bool = True) -> float:
    """Run one second of the demo (with a recording), a few env steps and the map tools;
    returns the wall time in seconds."""
    t0 = time.perf_counter()
    import gymnasium as gym

    import sim  # noqa: F401  (registers DepthNav-v0)
    from autonomy.maps.graph_builder import build_navgraph
    from autonomy.maps.graph_quality import graph_quality
    from sim.experiments.runner import run_scenario
    from sim.scenario import SCENARIOS_DIR, load_scenario
    from sim.simulator import blueprints

    with tempfile.TemporaryDirectory() as tmp:
        scn = load_scenario(SCENARIOS_DIR / "demo.toml", ["mission.max_duration_s=1.0", "report.figures=false"])
        run_scenario(scn, Path(tmp), rrd=Path(tmp) / "w.rrd", progress=False)
    env = gym.make("DepthNav-v0")
    env.reset(seed=0)
    for _ in range(3):
        env.step(env.action_space.sample())
    env.close()
    import numpy as np

    bp = blueprints.load_blueprint(blueprints.ASSETS_DIR / "small_floor")
    gb = build_navgraph(bp.vectormap)
    graph_quality(gb.graph, bp.vectormap, gb.free_space, np.random.default_rng(0), n_sources=1, n_targets=2)
    dt = time.perf_counter() - t0
    if verbose:
        print(f"depthnav: numba kernels compiled and cached in {dt:.1f} s", file=sys.stderr)
    return dt


if __name__ == "__main__":
    warm_up()
