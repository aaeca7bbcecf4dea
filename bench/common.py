"""Timing helpers shared by every benchmark group (bench/run.py and the subsystem files)."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

Result = dict[str, float | None]


def timeit(fn: Callable[[], object], repeat: int, warmup: int = 1) -> list[float]:
    """Wall times (ms) of ``repeat`` calls after ``warmup`` calls."""
    for _ in range(warmup):
        fn()
    out = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t) * 1e3)
    return out


def entry(samples: list[float], target: float | None = None, paper: float | None = None) -> Result:
    """One result row: median/min/max ms beside the project's target and the paper's figure."""
    return {
        "median_ms": round(float(np.median(samples)), 4),
        "min_ms": round(float(np.min(samples)), 4),
        "max_ms": round(float(np.max(samples)), 4),
        "target_ms": target,
        "paper_ms": None if paper is None else round(paper, 4),
    }
