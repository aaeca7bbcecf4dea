"""One writer for every run's JSON files (``report.json``, tables, incidents): whole or
not at all (:func:`autonomy.common.files.atomic_write_text`: a kill mid-write leaves the
file before), and valid JSON (NaN and infinities, which JSON lacks, become null; numpy
numbers and arrays plain numbers and lists)."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.files import atomic_write_text

__all__ = ["json_safe", "write_json"]


def json_safe(obj: Any) -> Any:
    """A copy of ``obj`` that :func:`json.dumps` writes as strict JSON."""
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def write_json(path: str | os.PathLike[str], obj: Any, indent: int | None = 2) -> Path:
    """Write ``obj`` to ``path`` as JSON (:func:`json_safe`), atomically."""
    return atomic_write_text(path, json.dumps(json_safe(obj), indent=indent, allow_nan=False) + "\n")
