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


def _register_envs() -> None:
    """Register the gymnasium environments (``DepthNav-v0``); mujoco is imported on make."""
    try:
        from gymnasium.envs.registration import register, registry
    except ImportError:  # pragma: no cover - gymnasium is a dependency
        return
    if "DepthNav-v0" not in registry:
        register(id="DepthNav-v0", entry_point="sim.envs.depthnav:DepthNavEnv")


_register_envs()
