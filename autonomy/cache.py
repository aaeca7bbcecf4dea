"""Where derived files of a map (its visibility grid, its automatic navigation graph) are
cached: beside the map file, else under ``~/.cache/depthnav`` (when there is no map file
or its directory is not writable)."""

from __future__ import annotations

import os
from pathlib import Path


def user_cache_dir() -> Path:
    """``~/.cache/depthnav`` (looked up at each call, so a changed HOME is honoured)."""
    return Path.home() / ".cache" / "depthnav"


def cache_paths(map_path: str | os.PathLike[str] | None, key: str, suffix: str) -> list[Path]:
    """Candidate cache files, in order of preference: ``<map file><suffix>``, then
    ``~/.cache/depthnav/<key prefix><suffix>``."""
    paths = []
    if map_path is not None:
        paths.append(Path(str(map_path) + suffix))
    paths.append(user_cache_dir() / f"{key[:32]}{suffix}")
    return paths
