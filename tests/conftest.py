"""Pytest configuration: headless EGL rendering unless the caller chose another backend.

Under ``make test`` (``DEPTHNAV_REQUIRE_GL=1``) a machine where no GL context opens stops
the run at once instead of skipping the rendering tests: the README's two commands set
GL up, so a skip there would hide a broken setup.

Property tests have no per-example deadline: they check answers, and a machine busy with
other jobs made a 0.3 s example fail one; speed is measured by ``make bench``.
"""

import os

import pytest
from hypothesis import settings

os.environ.setdefault("MUJOCO_GL", "egl")

settings.register_profile("depthnav", deadline=None)
settings.load_profile("depthnav")


def pytest_configure(config: pytest.Config) -> None:
    if os.environ.get("DEPTHNAV_REQUIRE_GL") == "1":
        from tests.helpers import GL

        if not GL:
            pytest.exit(f"no OpenGL context with MUJOCO_GL={os.environ['MUJOCO_GL']}: run `make gl` (Mesa's EGL)", returncode=3)
