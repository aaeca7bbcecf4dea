"""Shared test helpers: small synthetic worlds built from explicit segments, GL detection."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest

from autonomy.maps.vectormap import VectorMap


def box_room(w: float = 10.0, h: float = 6.0) -> VectorMap:
    """A closed w x h room with its corner at the origin."""
    return VectorMap.from_segments(np.array(box_segments(0, 0, w, h), dtype=np.float64), name="room")


def box_segments(
    x0: float, y0: float, x1: float, y1: float, gap: tuple[float, float] | None = None
) -> list[tuple[float, float, float, float]]:
    """A rectangle of walls as segment rows; ``gap`` cuts (from x, to x) out of the bottom wall."""
    bottom = [(x0, y0, x1, y0)] if gap is None else [(x0, y0, gap[0], y0), (gap[1], y0, x1, y0)]
    return bottom + [(x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]


def points_along(a, b, step: float = 0.05) -> np.ndarray:
    """Points from ``a`` to ``b`` (both ends included), at most ``step`` apart: a face as a
    scan holds it (one point per 5 cm cell)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    n = int(np.ceil(np.hypot(*(b - a)) / step)) + 1
    return a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)


def one_wall_depth(camera, wall_x: float) -> np.ndarray:
    """Exact planar depth (float32 m, 0 outside the camera's range) of the floor and the
    plane x = wall_x, seen by ``camera`` (an ``autonomy.perception.camera.DepthCamera``) from the
    origin facing +x: each pixel's ray through the mount, in closed form."""
    from autonomy.perception.camera import pixel_rays

    d = pixel_rays(camera.intrinsics).reshape(-1, 3) @ camera.mount.rotation().T  # robot frame, per unit of depth
    t = camera.mount.translation()
    with np.errstate(divide="ignore", invalid="ignore"):
        to_wall = np.where(d[:, 0] > 0, (wall_x - t[0]) / d[:, 0], np.inf)
        to_floor = np.where(d[:, 2] < 0, -t[2] / d[:, 2], np.inf)
    z = np.minimum(to_wall, to_floor)
    z = np.where((z >= camera.min_range_m) & (z <= camera.max_range_m), z, 0.0)
    return z.reshape(camera.intrinsics.height, camera.intrinsics.width).astype(np.float32)


def segments_map(rows) -> VectorMap:
    """A vector map of explicit segment rows."""
    return VectorMap.from_segments(np.array(rows, dtype=np.float64), name="test")


@pytest.fixture
def room() -> VectorMap:
    return box_room()


def gl_available() -> bool:
    """True when an EGL/OSMesa context can be made on this machine (tried in a child
    process: the test processes never load Mesa themselves, see sim.simulator.render_process)."""
    import subprocess
    import sys

    probe = "from mujoco import gl_context; gl_context.GLContext(64, 64).free()"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True, timeout=120).returncode == 0


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


def err_line(capsys) -> str:
    """The one stderr line a CLI user error prints (no traceback), for CLI tests."""
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def interrupt(proc, sig: int, ready, timeout_s: float = 60.0) -> str:
    """Wait until ``ready()`` is true, send ``sig`` to the child ``proc`` (as Ctrl-C or
    ``kill`` would), and return the rest of its stderr (stdout if merged). A child
    still running afterwards is killed, so no test leaves one behind."""
    import signal
    import time

    try:
        deadline = time.time() + timeout_s
        while time.time() < deadline and not ready():
            time.sleep(0.05)
        os.kill(proc.pid, sig)
        out, err = proc.communicate(timeout=timeout_s / 2)
        return err if err is not None else out
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(10)
