"""Pytest configuration: headless EGL rendering unless the caller chose another backend.

Under ``make test`` (``DEPTHNAV_REQUIRE_GL=1``) a machine where no GL context opens stops
the run at once instead of skipping the rendering tests: the README's two commands set
GL up, so a skip there would hide a broken setup.
"""

import os

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")


def pytest_configure(config: pytest.Config) -> None:
    if os.environ.get("DEPTHNAV_REQUIRE_GL") == "1":
        from tests.helpers import GL

        if not GL:
            pytest.exit(f"no OpenGL context with MUJOCO_GL={os.environ['MUJOCO_GL']}: run `make gl` (Mesa's EGL)", returncode=3)
