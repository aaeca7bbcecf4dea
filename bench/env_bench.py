"""Benchmarks of the gymnasium environment DepthNav-v0 (``bench_env``, a group of bench/run.py).

- ``env_step``: one env step of the default DepthNav-v0 (small_floor, 120 x 160 depth,
  Kinect noise, FSPF + CGR localization), random actions, in this process. Target 6.67 ms
  (150 steps/s). Resets (after collisions or the step limit) are timed apart.
- ``env_async2_step``: one step of an ``AsyncVectorEnv`` of two such envs (spawned
  workers); its steps/s (two env steps per vector step) go to stderr.

Run alone: ``.venv/bin/python bench/env_bench.py [--quick]``.
"""

from __future__ import annotations

import functools
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import Result  # noqa: E402
from common import entry as _entry  # noqa: E402


def bench_env(results: dict[str, Result], quick: bool) -> None:
    import sim  # noqa: F401  (registers DepthNav-v0)

    results["env_step"] = _bench_env_step(300 if quick else 2000)
    results["env_async2_step"] = _bench_async2_step(200 if quick else 1000)


def _bench_env_step(n: int) -> Result:
    """``n`` steps of one env in this process, random actions; resets are timed apart."""
    import gymnasium as gym

    env = gym.make("DepthNav-v0")
    env.action_space.seed(0)
    env.reset(seed=0)
    for _ in range(30):  # warm-up: GL context, numba kernels
        if any(env.step(env.action_space.sample())[2:4]):
            env.reset()
    steps: list[float] = []
    resets: list[float] = []
    t_all = time.perf_counter()
    for _ in range(n):
        a = env.action_space.sample()
        t = time.perf_counter()
        _, _, term, trunc, _ = env.step(a)
        steps.append((time.perf_counter() - t) * 1e3)
        if term or trunc:
            t = time.perf_counter()
            env.reset()
            resets.append((time.perf_counter() - t) * 1e3)
    wall = time.perf_counter() - t_all
    env.close()
    print(
        f"  env_step: {1000.0 / np.median(steps):.0f} steps/s (median step), {n / wall:.0f} steps/s overall "
        f"including {len(resets)} resets (median reset {np.median(resets) if resets else 0.0:.1f} ms)",
        file=sys.stderr,
    )
    return _entry(steps, target=round(1000.0 / 150.0, 2))


def _bench_async2_step(m: int) -> Result:
    """``m`` steps of an AsyncVectorEnv of two envs in spawned workers."""
    import gymnasium as gym

    from sim.envs.depthnav import DepthNavEnv

    # Spawned workers: a forked child cannot render once this process has used EGL.
    venv = gym.vector.AsyncVectorEnv([functools.partial(DepthNavEnv)] * 2, context="spawn")
    venv.action_space.seed(0)
    venv.reset(seed=[0, 1])
    for _ in range(30):
        venv.step(venv.action_space.sample())
    vsteps: list[float] = []
    t_all = time.perf_counter()
    for _ in range(m):
        a = venv.action_space.sample()
        t = time.perf_counter()
        venv.step(a)
        vsteps.append((time.perf_counter() - t) * 1e3)
    wall = time.perf_counter() - t_all
    venv.close()
    print(
        f"  env_async2_step: {2000.0 / np.median(vsteps):.0f} env steps/s (median vector step), "
        f"{2 * m / wall:.0f} env steps/s overall, 2 workers",
        file=sys.stderr,
    )
    return _entry(vsteps)


if __name__ == "__main__":
    res: dict[str, Result] = {}
    bench_env(res, "--quick" in sys.argv)
    for k, v in res.items():
        print(k, v)
