"""Seeded xorshift64* stream for the plane kernels (mirrors :mod:`autonomy.fspf`).

A numba kernel owns a one-element ``uint64`` state array; :func:`seed_state` turns any
integer seed into a non-zero state (splitmix64), so a seed gives the same draws on every
run on one machine.
"""

from __future__ import annotations

import numba
import numpy as np

_MASK64 = (1 << 64) - 1


def seed_state(seed: int) -> np.ndarray:
    """A one-element uint64 state array from any integer seed (splitmix64)."""
    z = (int(seed) + 0x9E3779B97F4A7C15) & _MASK64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    z ^= z >> 31
    return np.array([z or 1], dtype=np.uint64)


@numba.njit(cache=True, inline="always")
def next_u64(state):  # pragma: no cover - numba
    """Next 53-bit random integer of the stream."""
    x = state[0]
    x ^= x >> np.uint64(12)
    x ^= x << np.uint64(25)
    x ^= x >> np.uint64(27)
    state[0] = x
    return (x * np.uint64(2685821657736338717)) >> np.uint64(11)


@numba.njit(cache=True, inline="always")
def randbelow(state, n):  # pragma: no cover - numba
    """Uniform integer in [0, n) (n >= 1)."""
    return np.int64(next_u64(state) % np.uint64(n))
