"""One writer for every run's JSON files (``report.json``, tables, incidents, policy
evaluations): whole or not at all (:func:`autonomy.common.files.atomic_write_text`: a
kill mid-write leaves the file before), and valid JSON (NaN and infinities, which JSON
lacks, become null; numpy numbers and arrays plain numbers and lists; dataclasses their
fields). Configurations echoed into a report or hashed keep their infinities as text
(:func:`config_json`): ``inf`` there is a setting, not a missing figure."""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.files import atomic_write_text

__all__ = ["config_json", "json_safe", "write_json"]


def json_safe(obj: Any) -> Any:
    """A copy of ``obj`` that :func:`json.dumps` writes as strict JSON."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return json_safe(dataclasses.asdict(obj))
    if isinstance(obj, Mapping):
        return {str(k): json_safe(v) for k, v in obj.items()}
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
    """Write ``obj`` to ``path`` as JSON (:func:`json_safe`), atomically, making its folder."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_text(p, json.dumps(json_safe(obj), indent=indent, allow_nan=False) + "\n")


def config_json(x: Any) -> Any:
    """A configuration (:func:`sim.config.to_dict`'s plain values) as JSON: infinities and
    NaN as their text (``"inf"``), so that echoing or hashing a setting keeps it."""
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    if isinstance(x, dict):
        return {k: config_json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [config_json(v) for v in x]
    return x
