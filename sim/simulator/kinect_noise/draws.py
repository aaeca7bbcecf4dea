"""Counter-based random draws: one SplitMix64 word per pixel, and the normals made of
words (a 2048-quantile table for the lateral offsets, a 1024-layer ziggurat).

The hash is :func:`autonomy.common.rng.mix64`. Keys: :func:`seed_key` of the frame's
seed, :func:`field_key` of a frame or pattern key for the smooth fields.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numba
import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.rng import GAMMA, mix64, mix64_int

# Every pixel i = v * W + u owns one 64-bit word r = mix64(key + (i + 1) * gamma) (SplitMix64,
# Steele, Lea & Flood 2014, used as a counter-based generator). Its bits:
#   0-10 lateral u offset, 11-21 lateral v offset (index into LAT_G),
#   22-31 ziggurat layer, 32 sign, 33-47 ziggurat uniform (axial noise),
#   48-63 dropout uniform.
# The rare ziggurat wedge and tail tests hash r again for more words.

GAMMA64 = np.uint64(GAMMA)
_S11 = np.uint64(11)
_S22 = np.uint64(22)
_S32 = np.uint64(32)
_S33 = np.uint64(33)
_M15 = np.uint64(0x7FFF)
_ONE = np.uint64(1)
LAYER_MASK = np.uint64(0x3FF)
LAT_MASK = np.uint64(0x7FF)
_TWO_M53 = 2.0**-53
_TWO_M15 = 2.0**-15

# Ziggurat for the standard normal (Marsaglia & Tsang 2000) with 1024 layers: the fast
# path takes 99.6 % of draws. R (the base strip's edge) and V (every layer's area, for
# f(x) = exp(-x^2 / 2)) solve the closure of the top layer; found by bisection.
_ZIG_N = 1024
_ZIG_R = 4.038849846109504
_ZIG_V = 0.0012263246463530893


def _ziggurat_tables() -> tuple[np.ndarray, np.ndarray]:
    n = _ZIG_N
    x = np.zeros(n + 1)
    x[0] = _ZIG_V / math.exp(-0.5 * _ZIG_R * _ZIG_R)
    x[1] = _ZIG_R
    for i in range(1, n - 1):
        x[i + 1] = math.sqrt(-2.0 * math.log(_ZIG_V / x[i] + math.exp(-0.5 * x[i] * x[i])))
    x[n] = 0.0
    return x, np.exp(-0.5 * x * x)


_ZIG_X, _ZIG_F = _ziggurat_tables()
ZIG_X32 = _ZIG_X.astype(np.float32)  # the vectorised fast-path test

#: 2048 equiprobable standard-normal quantiles Phi^-1((i + 0.5) / 2048) (|g| <= 3.49). The
#: lateral offsets are rounded to whole pixels, so this discretised normal gets each offset's
#: probability right to 1/2048 for one table load.
LAT_G = np.array([NormalDist().inv_cdf((i + 0.5) / 2048) for i in range(2048)], dtype=np.float32)
LAT_G_MAX = float(np.abs(LAT_G).max())


@numba.njit(cache=True, inline="always")
def _uniform53(r):  # pragma: no cover - numba
    """Uniform in [0, 1) from the top 53 bits of a 64-bit word."""
    return float(np.int64(r >> _S11)) * _TWO_M53


@numba.njit(cache=True, inline="always")
def _zig_candidate(r):  # pragma: no cover - numba
    """Ziggurat candidate of a word: layer, sign (+-1) and x = U * X[layer]."""
    i = np.int64((r >> _S22) & LAYER_MASK)
    sgn = 1.0 - 2.0 * float(np.int64((r >> _S32) & _ONE))
    x = float(np.int32((r >> _S33) & _M15)) * _TWO_M15 * _ZIG_X[i]
    return i, sgn, x


@numba.njit(cache=True, error_model="numpy")
def normal_slow(r):  # pragma: no cover - numba
    """Standard normal of a word: the full ziggurat, more words chained by SplitMix64."""
    while True:
        i, sgn, x = _zig_candidate(r)
        if x < _ZIG_X[i + 1]:
            return sgn * x
        if i == 0:  # tail beyond R (Marsaglia 1964)
            while True:
                r = mix64(r + GAMMA64)
                xt = -math.log(1.0 - _uniform53(r)) / _ZIG_R
                r = mix64(r + GAMMA64)
                yt = -math.log(1.0 - _uniform53(r))
                if 2.0 * yt > xt * xt:
                    break
            return sgn * (_ZIG_R + xt)
        r = mix64(r + GAMMA64)  # wedge
        y = _ZIG_F[i] + _uniform53(r) * (_ZIG_F[i + 1] - _ZIG_F[i])
        if y < math.exp(-0.5 * x * x):
            return sgn * x
        r = mix64(r + GAMMA64)


@numba.njit(cache=True)
def normals(key, n, out):  # pragma: no cover - numba
    """n standard normals from the kernel's ziggurat and words (tests the generator)."""
    for i in range(n):
        out[i] = normal_slow(mix64(key + np.uint64(i + 1) * GAMMA64))


def check_seed(seed) -> int:
    """The seed as an int in [0, 2**64), or InputError."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise InputError(f"seed: expected an int, got {seed!r}")
    seed = int(seed)
    if not 0 <= seed < 2**64:
        raise InputError(f"seed: must be in [0, 2**64), got {seed}")
    return seed


def seed_key(seed: int) -> np.uint64:
    """Per-frame key: SplitMix64 of the seed (nearby seeds give unrelated streams)."""
    return np.uint64(mix64_int(seed * GAMMA + 0x632BE59BD9B4E019))


def field_key(key: np.uint64, tag: int) -> np.uint64:
    """Key of a field drawn from a frame or pattern key (tag 1: per-frame field, 2: pattern);
    unrelated to the per-pixel words of the same key."""
    return np.uint64(mix64_int(int(key) ^ (tag * 0xD1B54A32D192ED03)))
