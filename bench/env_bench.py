"""Benchmarks of the gymnasium environment DepthNav-v0 (``bench_env``, a group of bench/run.py).

- ``env_step``: the latency of one env step of the default DepthNav-v0 (small_floor,
  120 x 160 depth, Kinect noise, FSPF + CGR localization), random actions, in this
  process. Target 6.67 ms (150 steps/s). Resets (after collisions or the step limit) are
  timed apart.
- ``env_vec1``, ``env_vec2``, ``env_vec4``: throughput of the same env behind a gymnasium
  vector env of 1 (``SyncVectorEnv``, in this process), 2 and 4 (``AsyncVectorEnv``,
  spawned workers) envs, random actions, autoreset included. ``median_ms`` is the median
  vector step divided by the number of envs (time per env step); ``env_steps_per_s`` is
  env steps over the wall time of the whole run (resets included), and ``speedup`` that
  rate over ``env_vec1``'s.

- ``dec_point_vec1``, ``dec_point_vec2``, ``dec_local_vec1``, ``dec_local_vec2``: the same
  for the decision-level tasks ``DepthNavPointGoal-v0`` and ``DepthNavLocal-v0`` (a
  decision every six 30 Hz frames, one render, FSPF and CGR update per decision, the
  ranges and plan observations), in this process and behind 2 spawned workers:
  ``env_steps_per_s`` is decisions per second. Target with 2 workers: 500 decisions/s
  (2 ms a decision).

Run alone: ``.venv/bin/python bench/env_bench.py [--quick]``.
"""

from __future__ import annotations

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

#: Numbers of envs of the vectorized rows (``env_vec<n>``).
VEC_SIZES = (1, 2, 4)


def bench_env(results: dict[str, Result], quick: bool) -> None:
    import sim  # noqa: F401  (registers DepthNav-v0)

    results["env_step"] = _bench_env_step(300 if quick else 2000)
    base = None
    for n in VEC_SIZES:
        row = _bench_vec(n, 300 if quick else 2000)
        base = base or row["env_steps_per_s"]
        row["speedup"] = round(row["env_steps_per_s"] / base, 3)
        results[f"env_vec{n}"] = row
    from sim.envs.tasks import LOCALNAV, POINTNAV

    for short, task in (("point", POINTNAV), ("local", LOCALNAV)):
        one = _bench_vec(1, 150 if quick else 1000, task)
        two = _bench_vec(2, 150 if quick else 1000, task, target=2.0)
        two["speedup"] = round(two["env_steps_per_s"] / one["env_steps_per_s"], 3)
        results[f"dec_{short}_vec1"], results[f"dec_{short}_vec2"] = one, two
        print(
            f"  {task}: {one['env_steps_per_s']:.0f} decisions/s in one process, {two['env_steps_per_s']:.0f} with 2 workers",
            file=sys.stderr,
        )
    print(
        "  vectorized: " + ", ".join(f"{n} env(s) {results[f'env_vec{n}']['env_steps_per_s']:.0f} steps/s "
                                     f"(x{results[f'env_vec{n}']['speedup']:.2f})" for n in VEC_SIZES)
        + f" on {os.cpu_count()} cores",
        file=sys.stderr,
    )


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


def _bench_vec(n_envs: int, env_steps: int, task: str = "", target: float | None = None) -> Result:
    """About ``env_steps`` env steps through a vector env of ``n_envs`` envs: default
    DepthNavEnvs, or the registered ``task`` made with :func:`sim.envs.depthnav.make`."""
    import functools

    import gymnasium as gym

    from sim.envs.depthnav import DepthNavEnv, make

    factory = functools.partial(make, task) if task else DepthNavEnv
    if n_envs == 1:
        venv = gym.vector.SyncVectorEnv([factory])
    else:
        # Spawned workers: a forked child cannot render once this process has used EGL.
        venv = gym.vector.AsyncVectorEnv([factory] * n_envs, context="spawn")
    venv.action_space.seed(0)
    venv.reset(seed=0)
    for _ in range(30):  # warm-up in every env: GL context, numba kernels
        venv.step(venv.action_space.sample())
    m = max(1, env_steps // n_envs)
    vsteps: list[float] = []
    t_all = time.perf_counter()
    for _ in range(m):
        a = venv.action_space.sample()
        t = time.perf_counter()
        venv.step(a)
        vsteps.append((time.perf_counter() - t) * 1e3 / n_envs)
    wall = time.perf_counter() - t_all
    venv.close()
    row = _entry(vsteps, target=target)
    row["num_envs"] = n_envs
    row["env_steps_per_s"] = round(n_envs * m / wall, 1)
    return row


if __name__ == "__main__":
    res: dict[str, Result] = {}
    bench_env(res, "--quick" in sys.argv)
    for k, v in res.items():
        print(k, v)
