"""Time to the first frame of a run, cold and warm (``bench_start``, a group of bench/run.py).

- ``first_frame_warm``: wall time of ``depthnav run scenarios/demo.toml`` for its first
  0.1 s of simulated time in a fresh process (imports, world, GL context, the first frames)
  with numba's on-disk cache warm, as after ``make`` (which runs ``sim.warmup``).
- ``first_frame_cold``: the same with an empty numba cache: every kernel the run uses is
  compiled first (what a newcomer would wait without the warm-up; skipped with ``--quick``).

Run alone: ``.venv/bin/python bench/start_bench.py [--quick]``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import Result, entry  # noqa: E402


def _first_frame_s(env: dict[str, str]) -> float:
    with tempfile.TemporaryDirectory() as out:
        cmd = [sys.executable, "-m", "sim.cli", "run", str(ROOT / "scenarios" / "demo.toml"), "--out", out,
               "--set", "mission.max_duration_s=0.1", "--set", "report.figures=false"]
        t = time.perf_counter()
        p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
        dt = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(f"bench start: the run failed: {p.stderr.strip().splitlines()[-1:]}")
    return dt


def bench_start(results: dict[str, Result], quick: bool) -> None:
    env = dict(os.environ)
    env.setdefault("MUJOCO_GL", "egl")
    env.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".numba_cache"))
    _first_frame_s(env)  # make sure the cache is warm
    results["first_frame_warm"] = entry([1e3 * _first_frame_s(env) for _ in range(1 if quick else 3)], target=10_000.0)
    if not quick:
        with tempfile.TemporaryDirectory() as cache:
            cold = dict(env, NUMBA_CACHE_DIR=cache)
            results["first_frame_cold"] = entry([1e3 * _first_frame_s(cold)])


if __name__ == "__main__":
    from run import print_table

    res: dict[str, Result] = {}
    bench_start(res, "--quick" in sys.argv)
    print_table(res)
