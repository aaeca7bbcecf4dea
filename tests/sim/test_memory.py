"""Giving freed heap memory back to the system (sim/experiments/memory.py)."""

from __future__ import annotations

import platform

import numpy as np
import pytest

from sim.experiments.memory import _malloc_trim, release_free_memory, resident_mb


@pytest.mark.skipif(platform.system() != "Linux" or _malloc_trim() is None, reason="glibc's malloc_trim")
def test_freed_heap_pinned_by_a_live_chunk_is_returned() -> None:
    """60 MB of 32 kB arrays (below any mmap threshold, so on the heap), all freed but the
    last, which keeps the heap's top in use: free() alone leaves the 60 MB resident;
    release_free_memory hands it back."""
    base = resident_mb()
    chunks = [np.ones(4096) for _ in range(1800)]  # 32 kB each, written: resident
    pin = chunks[-1]
    assert resident_mb() - base > 50.0
    del chunks
    held = resident_mb()
    assert held - base > 50.0, "free() alone was expected to keep the heap resident"
    assert release_free_memory()
    assert held - resident_mb() > 45.0
    assert pin.sum() == 4096.0


def test_release_free_memory_is_safe_to_call_often() -> None:
    for _ in range(3):
        assert release_free_memory() in (True, False)
    assert 10.0 < resident_mb() < 1e5
