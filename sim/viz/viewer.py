"""The rerun viewer a run spawns (``--spawn``), found and checked without importing rerun."""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

from autonomy.common.errors import InputError


def viewer_executable() -> str:
    """The rerun viewer to spawn, checked before a run starts: an InputError if there is
    no display to open it on (the viewer would exit and the run block on sending to it)
    or no viewer installed. The one beside this Python (the venv's) is found without the
    venv on PATH."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise InputError("--spawn: no display to open the rerun viewer on (DISPLAY and WAYLAND_DISPLAY are not set); "
                         "record with --rrd FILE instead and open it where there is a display: rerun FILE")
    beside = Path(sys.executable).parent / ("rerun.exe" if sys.platform == "win32" else "rerun")
    found = str(beside) if beside.is_file() else shutil.which("rerun")
    if found is None:
        raise InputError("--spawn: the rerun viewer is not installed here (pip install rerun-sdk); or record with --rrd FILE")
    return found
