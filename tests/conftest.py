"""Pytest configuration: headless EGL rendering unless the caller chose another backend."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
