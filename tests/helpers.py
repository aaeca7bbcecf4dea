"""Shared test helpers: small synthetic worlds built from explicit segments, GL detection."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest

from autonomy.vectormap import VectorMap


def box_room(w: float = 10.0, h: float = 6.0) -> VectorMap:
    """A closed w x h room with its corner at the origin."""
    return VectorMap.from_segments(
        np.array([[0, 0, w, 0], [w, 0, w, h], [w, h, 0, h], [0, h, 0, 0]], dtype=np.float64), name="room"
    )


@pytest.fixture
def room() -> VectorMap:
    return box_room()


def gl_available() -> bool:
    """True when an EGL/OSMesa context can be made on this machine."""
    try:
        from mujoco import gl_context

        ctx = gl_context.GLContext(64, 64)
        ctx.free()
        return True
    except Exception:
        return False


GL = gl_available()


def rerun_cli() -> str | None:
    """The ``rerun`` command of this environment, if installed."""
    import shutil
    import sys
    from pathlib import Path

    exe = Path(sys.executable).parent / "rerun"
    return str(exe) if exe.exists() else shutil.which("rerun")


def rrd_chunks(path) -> list[tuple[str, str]]:
    """(entity path, data columns) of every chunk of an .rrd file, via ``rerun rrd print``.

    Also checks the file with ``rerun rrd verify``.
    """
    import re
    import subprocess

    cli = rerun_cli()
    assert cli is not None, "rerun CLI not installed"
    v = subprocess.run([cli, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)
    assert v.returncode == 0, v.stderr
    p = subprocess.run([cli, "rrd", "print", str(path)], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    return re.findall(r" - (/world[^ ]*) - data columns: \[([^\]]*)\]", p.stdout)
