"""The seeded xorshift64* random stream shared by the numba kernels (FSPF, RANSAC, Hough).

A kernel owns a one-element ``uint64`` state array; :func:`seed_u64` turns any integer
seed into a non-zero 64-bit state (splitmix64), so a seed gives the same draws on every
run, and a plain-Python mirror of the stream (tests) can reproduce a kernel's draws.
"""

from __future__ import annotations

import numba
import numpy as np

MASK64 = (1 << 64) - 1


def seed_u64(seed: int) -> int:
    """A non-zero 64-bit state from any integer seed (splitmix64)."""
    z = (int(seed) + 0x9E3779B97F4A7C15) & MASK64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
    z ^= z >> 31
    return z or 1


def seed_state(seed: int) -> np.ndarray:
    """A one-element uint64 state array from any integer seed."""
    return np.array([seed_u64(seed)], dtype=np.uint64)


@numba.njit(cache=True, inline="always")
def next_u64(state):  # pragma: no cover - numba
    """Next 53-bit random integer of the stream (xorshift64*)."""
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


@numba.njit(cache=True, inline="always")
def randint(state, lo, hi):  # pragma: no cover - numba
    """Uniform integer in [lo, hi]."""
    return lo + np.int64(next_u64(state) % np.uint64(hi - lo + 1))
