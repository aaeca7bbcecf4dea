"""Where derived files of a map (its visibility grid, its automatic navigation graph) are
cached: beside the map file, else under ``~/.cache/depthnav`` (when there is no map file
or its directory is not writable)."""

from __future__ import annotations

import os
import stat
from pathlib import Path


def user_cache_dir() -> Path:
    """``~/.cache/depthnav`` (looked up at each call, so a changed HOME is honoured)."""
    return Path.home() / ".cache" / "depthnav"


def cache_paths(map_path: str | os.PathLike[str] | None, key: str, suffix: str, for_writing: bool = False) -> list[Path]:
    """Candidate cache files, in order of preference: ``<map file><suffix>``, then
    ``~/.cache/depthnav/<key prefix><suffix>``. ``for_writing`` leaves out the place
    beside a map whose folder has no write bit for anyone: a folder of maps shared
    read-only stays untouched even by root, whom the permission check lets write."""
    paths = []
    if map_path is not None:
        beside = Path(str(map_path) + suffix)
        if not for_writing or _has_write_bit(beside.parent):
            paths.append(beside)
    paths.append(user_cache_dir() / f"{key[:32]}{suffix}")
    return paths


def _has_write_bit(folder: Path) -> bool:
    try:
        return bool(folder.stat().st_mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    except OSError:
        return False
