"""Smooth random fields: the per-frame correlated axial field and the sensor's fixed
disparity pattern.

A unit-variance Gaussian random field with autocorrelation close to exp(-(r / L)^2), made
cheaply: white normals on a coarse grid (cell c ~ L / 2 px) are filtered by a separable
Gaussian kernel, then interpolated bilinearly to the pixels. The kernel's width takes off
what the interpolation adds (per axis, the autocorrelation's second moment L^2 / 2 is
2 s^2 from the kernel plus c^2 / 3 from the bilinear weights), and each pixel's weights
are divided by the standard deviation of the interpolated value at its position within
the cell, so the variance is 1 at every pixel. Rows are interpolated horizontally once per
coarse row (``hrows``); a pixel row is then a blend of two of them.
"""

from __future__ import annotations

import functools
import math
import threading

import numba
import numpy as np

from autonomy.common.rng import mix64
from autonomy.perception.camera import CameraIntrinsics
from sim.simulator.kinect_noise.config import KinectNoiseConfig
from sim.simulator.kinect_noise.draws import GAMMA64, check_seed, field_key, normal_slow, seed_key


@numba.njit(cache=True, nogil=True, error_model="numpy")
def field_block(key, kern, nx, j0, j1, iu, wu0, wu1):  # pragma: no cover - numba
    """Coarse rows j0..j1 of a smooth field, interpolated to the pixel columns ((j1 - j0 + 1)
    x width, float32). The coarse field is white normals (words of key; node (i, j) of the
    grid padded by the kernel's radius r has counter i (nx + 2 r) + j + 1) filtered along
    both axes by kern (whose squares sum to 1: unit variance); any range of rows comes out
    the same as in the whole field, so image blocks can each make their own."""
    r = (kern.size - 1) // 2
    wx = nx + 2 * r
    nr = j1 - j0 + 1
    tmp = np.zeros((nr + 2 * r, nx))
    white = np.empty(wx)
    for i in range(nr + 2 * r):
        base = (j0 + i) * wx
        for j in range(wx):
            white[j] = normal_slow(mix64(key + np.uint64(base + j + 1) * GAMMA64))
        for j in range(nx):
            acc = 0.0
            for t in range(kern.size):
                acc += kern[t] * white[j + t]
            tmp[i, j] = acc
    out = np.empty((nr, iu.size), dtype=np.float32)
    crow = np.zeros(nx)
    for i in range(nr):
        crow[:] = 0.0
        for t in range(kern.size):
            kt = kern[t]
            for j in range(nx):
                crow[j] += kt * tmp[i + t, j]
        orow = out[i]
        for u in range(iu.size):
            orow[u] = wu0[u] * crow[iu[u]] + wu1[u] * crow[iu[u] + 1]
    return out


@functools.lru_cache(maxsize=16)
def _field_plan(h: int, w: int, length_px: float) -> tuple:
    """Geometry of a field of correlation length ``length_px`` on an h x w image: cell size,
    kernel, and per column and per row the coarse index and the two normalised weights."""
    c = max(1, round(length_px / 2.0))
    sk = math.sqrt(max(length_px * length_px / 4.0 - c * c / 6.0, (0.5 * c) ** 2)) / c
    r = max(1, math.ceil(3.0 * sk))
    kern = np.exp(-0.5 * (np.arange(-r, r + 1) / sk) ** 2)
    kern /= math.sqrt(float((kern * kern).sum()))
    rho1 = float((kern[:-1] * kern[1:]).sum())  # correlation of neighbouring coarse nodes

    def axis(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i = np.arange(n) // c
        f = (np.arange(n) - i * c) / c
        sd = np.sqrt((1 - f) ** 2 + f * f + 2 * f * (1 - f) * rho1)
        return i.astype(np.int32), ((1 - f) / sd).astype(np.float32), (f / sd).astype(np.float32)

    ny, nx = (h - 1) // c + 2, (w - 1) // c + 2
    return ny, nx, kern, axis(w), axis(h)


def _field_rows(key: np.uint64, h: int, w: int, length_px: float) -> tuple[np.ndarray, ...]:
    """A unit-variance field of correlation length ``length_px`` as (hrows, rj, rw0, rw1):
    pixel (v, u) is rw0[v] hrows[rj[v], u] + rw1[v] hrows[rj[v] + 1, u]."""
    ny, nx, kern, (iu, wu0, wu1), (rj, rw0, rw1) = _field_plan(h, w, float(length_px))
    return field_block(key, kern, nx, 0, ny - 1, iu, wu0, wu1), rj, rw0, rw1


def field_arg(key: np.uint64, h: int, w: int, length_px: float) -> tuple:
    """The kernel's field argument: each image block makes the coarse rows it needs."""
    ny, nx, kern, (iu, wu0, wu1), (rj, rw0, rw1) = _field_plan(h, w, float(length_px))
    return (True, key, kern, nx, iu, wu0, wu1, rj, rw0, rw1)


@functools.lru_cache(maxsize=8)
def no_field(shape: tuple[int, int]) -> tuple:
    """The kernel's field argument when the correlated term is off (cached; never written)."""
    ny, nx, kern, (iu, wu0, wu1), (rj, rw0, rw1) = _field_plan(shape[0], shape[1], 2.0)
    return (False, np.uint64(0), kern, nx, iu, wu0, wu1, rj, rw0, rw1)


def smooth_field(seed: int, h: int, w: int, length_px: float) -> np.ndarray:
    """The h x w unit-variance random field of correlation length ``length_px`` (in image px)
    that a seed gives (float32): what the correlated terms add, before their scale."""
    hrows, rj, rw0, rw1 = _field_rows(field_key(seed_key(check_seed(seed)), 1), h, w, length_px)
    return rw0[:, None] * hrows[rj] + rw1[:, None] * hrows[rj + 1]


_EMPTY_PATTERN = np.zeros((1, 1), dtype=np.float32)
_EMPTY_PATTERN.setflags(write=False)  # the same array type as a pattern image


def no_pattern() -> tuple:
    """The kernel's pattern argument when the fixed pattern is off."""
    return (False, _EMPTY_PATTERN)


def pattern_on(cfg: KinectNoiseConfig) -> bool:
    """Whether ``cfg`` adds a fixed pattern (on, with a spread above 0)."""
    return bool(cfg.pattern and cfg.pattern_sigma_px > 0)


_pattern_lock = threading.Lock()
_patterns: dict[tuple, np.ndarray] = {}


def pattern_image(cfg: KinectNoiseConfig, h: int, w: int, scale: float) -> np.ndarray:
    """The fixed pattern of ``cfg.pattern_seed`` in 1/subpixel px of disparity of the
    focal_px camera, the kernel's unit (h x w, float32, read-only), made once per sensor and
    image geometry and then reused; ``scale`` turns its correlation length into image px."""
    k = (cfg.pattern_seed, h, w, float(cfg.pattern_length_px * scale),
         float(cfg.pattern_sigma_px * cfg.subpixel))  # fmt: skip
    with _pattern_lock:
        img = _patterns.get(k)
        if img is None:
            hrows, rj, rw0, rw1 = _field_rows(field_key(seed_key(k[0]), 2), h, w, k[3])
            f = (rw0[:, None] * hrows[rj] + rw1[:, None] * hrows[rj + 1]).astype(np.float64)
            # Over one image a field this smooth has few independent samples: its mean and
            # spread vary from sensor to sensor. Each pattern is made zero-mean with exactly
            # the configured spread, so sensors differ in shape only.
            f -= f.mean()
            f *= k[4] / max(float(f.std()), 1e-12)
            img = f.astype(np.float32)
            img.setflags(write=False)
            if len(_patterns) >= 8:
                _patterns.clear()
            _patterns[k] = img
    return img


def pattern_disparity_px(cfg: KinectNoiseConfig, intr: CameraIntrinsics) -> np.ndarray:
    """The fixed disparity pattern that ``cfg`` adds (H x W float32, px of the focal_px
    camera, like the disparity the model quantises); 0 when the pattern is off."""
    if not pattern_on(cfg):
        return np.zeros((intr.height, intr.width), dtype=np.float32)
    scale = intr.fx / cfg.focal_px
    return pattern_image(cfg, intr.height, intr.width, scale) / np.float32(cfg.subpixel)
