"""The project's one SplitMix64 hash (autonomy.common.rng.mix64): the reference generator's
outputs, the same words in numba kernels and in Python, and the seeding built on it."""

from __future__ import annotations

import numba
import numpy as np

from autonomy.common.rng import GAMMA, MASK64, mix64, mix64_int, seed_u64

#: The first outputs of SplitMix64 (Vigna's splitmix64.c) seeded with 1234567.
SPLITMIX64_1234567 = [
    6457827717110365317, 3203168211198807973, 9817491932198370423, 4593380528125082431,
    16408922859458223821,
]  # fmt: skip


@numba.njit
def _words(key, n, out):
    for i in range(n):
        out[i] = mix64(key + np.uint64(i + 1) * np.uint64(GAMMA))


def test_mix64_is_splitmix64() -> None:
    state, out = 1234567, []
    for _ in range(len(SPLITMIX64_1234567)):
        state = (state + GAMMA) & MASK64
        out.append(mix64_int(state))
    assert out == SPLITMIX64_1234567


def test_kernels_and_python_draw_the_same_words() -> None:
    key = 2**63 + 12345
    got = np.empty(1000, dtype=np.uint64)
    _words(np.uint64(key), got.size, got)
    assert [int(g) for g in got] == [mix64_int(key + (i + 1) * GAMMA) for i in range(got.size)]
    ref = np.empty(len(SPLITMIX64_1234567), dtype=np.uint64)
    _words(np.uint64(1234567), ref.size, ref)
    assert ref.tolist() == SPLITMIX64_1234567


def test_seed_u64_is_the_first_splitmix64_output_and_never_zero() -> None:
    assert seed_u64(1234567) == SPLITMIX64_1234567[0]
    assert seed_u64(1234567 + 2**64) == seed_u64(1234567)  # any integer, taken modulo 2**64
    zero_at = (-GAMMA) & MASK64  # mix64(0) == 0: that seed gets the state 1
    assert mix64_int(0) == 0 and seed_u64(zero_at) == 1
