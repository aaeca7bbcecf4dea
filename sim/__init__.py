"""Everything that only exists in simulation: worlds, the robot, the Kinect model, runs.

Headless rendering defaults to EGL (Mesa on CPU machines); set ``MUJOCO_GL`` before
importing ``sim`` to choose another backend. Where no GL context can be made, the
depth camera falls back to ray casting (:mod:`sim.simulator.kinect`).
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"] if os.environ["MUJOCO_GL"] in ("egl", "osmesa") else "")
if not os.environ["PYOPENGL_PLATFORM"]:
    del os.environ["PYOPENGL_PLATFORM"]


#: ``max_episode_steps`` of ``DepthNav-v0``: the benchmark task's ``max_steps``
#: (``sim.rl.splits.BENCHMARK_TASK``), also ``EnvConfig``'s default (tests/test_env.py
#: checks both). ``gymnasium.make`` wraps the env in a ``TimeLimit`` of this many steps
#: unless given ``max_episode_steps``; ``sim.envs.depthnav.make`` gives it the env's own
#: ``max_steps``.
MAX_EPISODE_STEPS = 1000


def _register_envs() -> None:
    """Register the gymnasium environments (:mod:`sim.envs.tasks`); mujoco is imported on make."""
    try:
        from gymnasium.envs.registration import register, registry
    except ImportError:  # pragma: no cover - gymnasium is a dependency
        return
    from sim.envs.tasks import TASKS, max_episode_steps

    for task, fixed in TASKS.items():
        if task not in registry:
            steps = MAX_EPISODE_STEPS if task == "DepthNav-v0" else max_episode_steps(task)
            register(id=task, entry_point="sim.envs.depthnav:DepthNavEnv", max_episode_steps=steps, kwargs=dict(fixed))


_register_envs()
