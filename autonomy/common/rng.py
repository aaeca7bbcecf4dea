"""The project's random numbers: SplitMix64 hashing and the seeded xorshift64* stream.

:func:`mix64` is SplitMix64's finaliser (Steele, Lea & Flood 2014), the one 64-bit hash
of the project: it seeds the streams here and makes the Kinect noise model's
counter-based words (``sim.simulator.kinect_noise``). It runs in numba kernels and, on
Python integers, through :func:`mix64_int`.

The xorshift64* stream is shared by the numba kernels (FSPF, RANSAC, Hough). A kernel
owns a one-element ``uint64`` state array; :func:`seed_u64` turns any integer seed into a
non-zero 64-bit state (splitmix64), so a seed gives the same draws on every run, and a
plain-Python mirror of the stream (tests) can reproduce a kernel's draws.
"""

from __future__ import annotations

import numba
import numpy as np

MASK64 = (1 << 64) - 1

#: SplitMix64's increment, 2**64 / golden ratio: counter i of a key k is k + i * GAMMA.
GAMMA = 0x9E3779B97F4A7C15
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S27 = np.uint64(27)
_S30 = np.uint64(30)
_S31 = np.uint64(31)


@numba.njit(cache=True, inline="always")
def mix64(s):
    """SplitMix64's finaliser of a ``uint64`` word (Steele, Lea & Flood 2014)."""
    s = (s ^ (s >> _S30)) * _M1
    s = (s ^ (s >> _S27)) * _M2
    return s ^ (s >> _S31)


def mix64_int(x: int) -> int:
    """:func:`mix64` of a Python integer, taken modulo 2**64."""
    return int(mix64(np.uint64(int(x) & MASK64)))


def seed_u64(seed: int) -> int:
    """A non-zero 64-bit state from any integer seed (splitmix64)."""
    return mix64_int(int(seed) + GAMMA) or 1


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
