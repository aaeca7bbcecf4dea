"""Kinect v1 depth-noise model applied to a clean planar depth image.

Terms (each switchable in :class:`KinectNoiseConfig`), applied in this order:

1. Incidence angle ``theta`` per pixel from normals of the *clean* image
   (:func:`incidence_angle`).
2. Projector shadows: pixels the IR projector cannot see are 0 (per-row epipolar scan).
3. Lateral noise (Nguyen, Izadi & Lovell 2012, eq. for sigma_L): each output pixel takes
   the depth of the pixel at a Gaussian offset (rounded, clamped to the image), which
   blurs depth edges.
4. Axial noise (same paper): Gaussian sigma_z(z, theta) added to z, per pixel in the
   independent model; in the correlated model (the default) partly as a smooth field.
5. Disparity quantisation: d = f b / z in 1/8 px steps (Kinect v1, docs/architecture.md), after the
   fixed disparity pattern (default on) is added to d.
6. Range cut [min_range_m, max_range_m] on the measured depth.
7. Dropouts rising linearly with theta between 70 and 85 degrees, plus an optional
   uniform dropout rate.

The correlated model. A Kinect v1 does not measure depth pixel by pixel: it block-matches
the projected speckle pattern over a correlation window (9 x 9 or 9 x 7 px, to 1/8 px;
Konolige & Mihelich, ROS kinect_calibration technical description), so its depth is
locally smooth, shows wide bands of one disparity step on a flat wall, and carries a fixed
spatial distortion of its own (Smisek, Jancosek & Pajdla 2011; Herrera, Kannala & Heikkila
2012; Clarkson et al. 2013: a plane filling the view comes back non-planar in a pattern
that stays with the sensor). Two terms model this:

- Spatially correlated axial noise (``correlated``): Nguyen's sigma_z = a + qz (+ the
  grazing term), qz = b (z - z0)^2. Our reading of its two terms: the range term qz, which
  grows like the disparity error (z^2), is the block-matched error and is correlated; the
  constant a is per pixel. The split keeps sigma_z per pixel: the share
  qz^2 / (a^2 + qz^2) of sigma_z^2 goes to a unit-variance Gaussian field of correlation
  length ``corr_length_px`` (autocorrelation exp(-(r / L)^2)), new every frame; the rest
  stays independent from pixel to pixel. At 1 m the field holds 25 % of the variance, at
  3 m 99 %. L = 32 px: the sources give no length; the correlation window (9 px) is its
  lower bound. FSPF with BV2012 Table I's parameters, which BV2012 ran on real frames to
  the sensor's range, finds planes on a wall at 3.5 m from L = 16 px on, after sampling
  7,000-13,000 of its 20,000 neighbourhoods, and after 650-1,100 from L = 32 px on
  (docs/kinect_noise.md has the measurements); 32 px is the value we took.
- Fixed pattern (``pattern``), the temporal term: a smooth disparity offset per pixel,
  the same in every frame of a sensor (``pattern_seed``), added to d before the 1/8 px
  rounding, so its depth effect grows like z^2 / (f b). Standard deviation
  ``pattern_sigma_px`` = 0.09 px, fitted on the mapping_wall scenario (seed 5) to PlaneMap's
  Table III (a real Kinect facing a wall at 1.06 m and 1.56 m: 3.9 / 8.8 mm with RANSAC,
  2.5 / 7.4 mm with Hough), whose spread is about twice Nguyen's sigma_z; correlation
  length ``pattern_length_px`` = 96 px (our choice: the sources show the pattern over the
  whole view but give no length). With it, errors are correlated in time in part: at a
  pixel, the pattern's share of the variance.

``correlated=False, pattern=False`` is the independent model.

Randomness is counter based: pixel i of a frame draws one 64-bit word, a SplitMix64 hash
of (seed, i) (Steele, Lea & Flood 2014), whose bits give the two lateral offsets (a
2048-quantile normal table), the axial normal (a 1024-layer ziggurat, Marsaglia & Tsang
2000) and the dropout uniform. The smooth fields draw their coarse-grid normals from words
of keys derived from the frame's seed (the correlated field) and from ``pattern_seed`` (the
pattern). The output depends only on the inputs, the config and the seed (never on call
history, global RNG state or the thread count): same seed, same image, bit for bit.

Speed: per row, vectorised float32 loops (normals, incidence angles, the final arithmetic)
and lean scalar loops (table lookups, gathers, the shadow scan). The image is split into
``cfg.threads`` row blocks run on threads with the GIL released; each block computes its
own halo rows, so blocks need no synchronisation. ``python bench/noise_bench.py`` times it.

Choices where the sources leave room: an output pixel whose own input is invalid stays 0
(holes are not filled by the lateral jitter; a shadowed pixel can take a lit neighbour's
depth); sigma_z and the dropout probability are those of the source pixel (its clean
depth and theta); sigma_L is in pixels of a ``focal_px`` camera and scales with
``intr.fx``; the range cut applies to the measured (noisy, quantised) depth; theta is
clamped to 89 degrees in the closed forms. Nguyen et al. measured sigma_z on the sensor's
quantised output; as specified for this module we still add quantisation on top
(variance about sigma_z^2 + step^2 / 12).
"""

from __future__ import annotations

import functools
import math
import os
import queue
import threading
from dataclasses import dataclass, fields
from statistics import NormalDist

import numba
import numpy as np

from autonomy.common.constants import KINECT_FOCAL_PX, KINECT_MAX_RANGE_M, KINECT_MIN_RANGE_M
from autonomy.common.errors import InputError
from autonomy.common.rng import GAMMA, mix64, mix64_int
from autonomy.perception.camera import CameraIntrinsics

#: Incidence angles are clamped below this in the closed forms (both blow up at pi/2).
THETA_MAX_RAD = math.radians(89.0)


@dataclass(frozen=True)
class KinectNoiseConfig:
    """Parameters of the Kinect v1 noise model (Nguyen, Izadi & Lovell 2012; docs/architecture.md)."""

    axial: bool = True
    """Add Gaussian axial noise sigma_z(z, theta)."""
    axial_a_m: float = 0.0012
    """Constant term of sigma_z (Nguyen et al.: 0.0012 m)."""
    axial_b_per_m: float = 0.0019
    """Quadratic coefficient of sigma_z in (z - z0)^2 (0.0019 1/m)."""
    axial_z0_m: float = 0.4
    """Depth z0 of the quadratic's vertex (0.4 m)."""
    axial_grazing_m: float = 0.0001
    """Grazing-term coefficient of sigma_z: c / sqrt(z) * theta^2 / (pi/2 - theta)^2 (0.0001)."""
    axial_grazing_start_rad: float = math.radians(60.0)
    """Incidence angle above which the grazing term is added (60 degrees)."""
    correlated: bool = True
    """Spatially correlated axial noise: the share qz^2 / (a^2 + qz^2) of sigma_z^2, with a
    its constant and qz = b (z - z0)^2 its range term, is a smooth random field; the rest
    stays per pixel. False: all of sigma_z is independent from pixel to pixel (the
    independent model)."""
    corr_length_px: float = 32.0
    """Correlation length L of that field (px of the focal_px camera): its autocorrelation
    is exp(-(r / L)^2)."""
    pattern: bool = True
    """Add the sensor's fixed disparity pattern: the same in every frame of a run."""
    pattern_sigma_px: float = 0.09
    """Standard deviation of the fixed pattern in disparity over the image (px of the
    focal_px camera); the pattern has zero mean."""
    pattern_length_px: float = 96.0
    """Correlation length of the fixed pattern (px of the focal_px camera)."""
    pattern_seed: int = 0
    """Which sensor: the seed of the fixed pattern (independent of the per-frame seed)."""
    lateral: bool = True
    """Jitter each pixel's source position by the lateral noise sigma_L(theta)."""
    lateral_a_px: float = 0.8
    """Constant term of sigma_L in pixels of the 580 px camera (0.8 px)."""
    lateral_b_px: float = 0.035
    """Coefficient of theta / (pi/2 - theta) in sigma_L (0.035 px)."""
    quantize: bool = True
    """Quantise the disparity d = f b / z to 1/subpixel px."""
    focal_px: float = KINECT_FOCAL_PX
    """Focal length f of the IR camera used for disparity (px)."""
    baseline_m: float = 0.075
    """Projector-camera baseline b used for disparity (m)."""
    subpixel: int = 8
    """Disparity steps per pixel (Kinect v1: 1/8 px)."""
    min_range_m: float = KINECT_MIN_RANGE_M
    """Measured depths below this become 0."""
    max_range_m: float = KINECT_MAX_RANGE_M
    """Measured depths above this become 0 (may be inf)."""
    shadows: bool = True
    """Zero the pixels the IR projector cannot see."""
    projector_offset_m: float = 0.075
    """Projector position along the optical x axis from the camera (+ = right in the image)."""
    dropouts: bool = True
    """Drop pixels seen at grazing incidence."""
    dropout_start_rad: float = math.radians(70.0)
    """Incidence angle where the dropout probability starts rising from 0."""
    dropout_full_rad: float = math.radians(85.0)
    """Incidence angle where the dropout probability reaches 1."""
    dropout_rate: float = 0.0
    """Extra uniform dropout probability for every valid pixel (when dropouts is on)."""
    normal_max_rel_jump: float = 0.05
    """Neighbour depth jump (relative to z) beyond which it is not used for the normal."""
    threads: int = 2
    """Threads for the kernels (capped at the CPU count); the output does not depend on it."""

    def __post_init__(self) -> None:
        self._check_types()
        self._check_ranges()

    def _check_types(self) -> None:
        """Bools are bools, ``subpixel`` and ``threads`` positive ints, ``pattern_seed`` an
        int in [0, 2**64), the rest finite numbers (``max_range_m`` may be inf)."""
        for fd in fields(self):
            val = getattr(self, fd.name)
            if fd.type in ("bool", bool):
                if not isinstance(val, bool | np.bool_):
                    raise InputError(f"KinectNoiseConfig.{fd.name}: expected a bool, got {val!r}")
            elif fd.name == "pattern_seed":
                if isinstance(val, bool) or not isinstance(val, int | np.integer) or not 0 <= val < 2**64:
                    raise InputError(f"KinectNoiseConfig.{fd.name}: expected an int in [0, 2**64), got {val!r}")
            elif fd.name in ("subpixel", "threads"):
                if isinstance(val, bool) or not isinstance(val, int | np.integer) or val <= 0:
                    raise InputError(
                        f"KinectNoiseConfig.{fd.name}: expected a positive int, got {val!r}"
                    )
            else:
                if isinstance(val, bool) or not isinstance(
                    val, int | float | np.integer | np.floating
                ):
                    raise InputError(f"KinectNoiseConfig.{fd.name}: expected a number, got {val!r}")
                if math.isnan(val) or (math.isinf(val) and fd.name != "max_range_m"):
                    raise InputError(f"KinectNoiseConfig.{fd.name}: must be finite, got {val!r}")

    def _check_ranges(self) -> None:
        def need(ok: bool, name: str, what: str) -> None:
            if not ok:
                raise InputError(f"KinectNoiseConfig.{name}: {what}, got {getattr(self, name)!r}")

        need(self.axial_a_m >= 0, "axial_a_m", "must be >= 0")
        need(self.axial_b_per_m >= 0, "axial_b_per_m", "must be >= 0")
        need(self.axial_grazing_m >= 0, "axial_grazing_m", "must be >= 0")
        need(
            0 <= self.axial_grazing_start_rad < math.pi / 2,
            "axial_grazing_start_rad",
            "must be in [0, pi/2)",
        )
        need(self.corr_length_px > 0, "corr_length_px", "must be > 0")
        need(self.pattern_sigma_px >= 0, "pattern_sigma_px", "must be >= 0")
        need(self.pattern_length_px > 0, "pattern_length_px", "must be > 0")
        need(self.lateral_a_px >= 0, "lateral_a_px", "must be >= 0")
        need(self.lateral_b_px >= 0, "lateral_b_px", "must be >= 0")
        need(self.focal_px > 0, "focal_px", "must be > 0")
        need(self.baseline_m > 0, "baseline_m", "must be > 0")
        need(self.min_range_m >= 0, "min_range_m", "must be >= 0")
        need(
            self.max_range_m > self.min_range_m,
            "max_range_m",
            f"must be > min_range_m={self.min_range_m}",
        )
        need(
            0 <= self.dropout_start_rad <= math.pi / 2, "dropout_start_rad", "must be in [0, pi/2]"
        )
        need(
            self.dropout_start_rad < self.dropout_full_rad <= math.pi / 2,
            "dropout_full_rad",
            f"must be in (dropout_start_rad={self.dropout_start_rad:.4f}, pi/2]",
        )
        need(0 <= self.dropout_rate <= 1, "dropout_rate", "must be in [0, 1]")
        need(self.normal_max_rel_jump > 0, "normal_max_rel_jump", "must be > 0")


# --------------------------------------------------------------------------- closed forms


def axial_sigma_m(z, theta, cfg: KinectNoiseConfig | None = None) -> np.ndarray:
    """Axial noise sigma_z(z, theta) in metres (Nguyen, Izadi & Lovell 2012, Sec. 3).

    0.0012 + 0.0019 (z - 0.4)^2, plus 0.0001 / sqrt(z) * theta^2 / (pi/2 - theta)^2 for
    theta > 60 degrees. theta is clamped to :data:`THETA_MAX_RAD`.
    """
    c = cfg or KinectNoiseConfig()
    z = np.asarray(z, dtype=np.float64)
    th = np.minimum(np.asarray(theta, dtype=np.float64), THETA_MAX_RAD)
    s = c.axial_a_m + c.axial_b_per_m * (z - c.axial_z0_m) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        graze = c.axial_grazing_m / np.sqrt(z) * th**2 / (math.pi / 2 - th) ** 2
    return np.where(th > c.axial_grazing_start_rad, s + graze, s)


def lateral_sigma_px(theta, cfg: KinectNoiseConfig | None = None) -> np.ndarray:
    """Lateral noise sigma_L(theta) = 0.8 + 0.035 theta / (pi/2 - theta) px (Nguyen et al. 2012).

    In pixels of a camera with ``cfg.focal_px``; theta is clamped to :data:`THETA_MAX_RAD`.
    """
    c = cfg or KinectNoiseConfig()
    th = np.minimum(np.asarray(theta, dtype=np.float64), THETA_MAX_RAD)
    return c.lateral_a_px + c.lateral_b_px * th / (math.pi / 2 - th)


def depth_step_m(z, cfg: KinectNoiseConfig | None = None) -> np.ndarray:
    """Depth spacing of the disparity grid at z, to first order z^2 / (subpixel f b).

    2.9 mm at 1 m and 46 mm at 4 m for the Kinect v1 defaults (docs/architecture.md).
    """
    c = cfg or KinectNoiseConfig()
    z = np.asarray(z, dtype=np.float64)
    return z * z / (c.subpixel * c.focal_px * c.baseline_m)


def dropout_probability(theta, cfg: KinectNoiseConfig | None = None) -> np.ndarray:
    """Grazing-angle dropout probability: linear from 0 at dropout_start_rad to 1 at dropout_full_rad."""
    c = cfg or KinectNoiseConfig()
    th = np.asarray(theta, dtype=np.float64)
    return np.clip(
        (th - c.dropout_start_rad) / (c.dropout_full_rad - c.dropout_start_rad), 0.0, 1.0
    )


# --------------------------------------------------------------------------- random numbers
#
# Every pixel i = v * W + u owns one 64-bit word r = mix64(key + (i + 1) * gamma) (SplitMix64,
# Steele, Lea & Flood 2014, used as a counter-based generator). Its bits:
#   0-10 lateral u offset, 11-21 lateral v offset (index into _LAT_G),
#   22-31 ziggurat layer, 32 sign, 33-47 ziggurat uniform (axial noise),
#   48-63 dropout uniform.
# The rare ziggurat wedge and tail tests hash r again for more words.

_GAMMA = np.uint64(GAMMA)
_S11 = np.uint64(11)
_S22 = np.uint64(22)
_S32 = np.uint64(32)
_S33 = np.uint64(33)
_M15 = np.uint64(0x7FFF)
_ONE = np.uint64(1)
_LAYER_MASK = np.uint64(0x3FF)
_LAT_MASK = np.uint64(0x7FF)
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
_ZIG_X32 = _ZIG_X.astype(np.float32)  # the vectorised fast-path test

#: 2048 equiprobable standard-normal quantiles Phi^-1((i + 0.5) / 2048) (|g| <= 3.49). The
#: lateral offsets are rounded to whole pixels, so this discretised normal gets each offset's
#: probability right to 1/2048 for one table load.
_LAT_G = np.array([NormalDist().inv_cdf((i + 0.5) / 2048) for i in range(2048)], dtype=np.float32)
_LAT_G_MAX = float(np.abs(_LAT_G).max())


@numba.njit(cache=True, inline="always")
def _uniform53(r):  # pragma: no cover - numba
    """Uniform in [0, 1) from the top 53 bits of a 64-bit word."""
    return float(np.int64(r >> _S11)) * _TWO_M53


@numba.njit(cache=True, inline="always")
def _zig_candidate(r):  # pragma: no cover - numba
    """Ziggurat candidate of a word: layer, sign (+-1) and x = U * X[layer]."""
    i = np.int64((r >> _S22) & _LAYER_MASK)
    sgn = 1.0 - 2.0 * float(np.int64((r >> _S32) & _ONE))
    x = float(np.int32((r >> _S33) & _M15)) * _TWO_M15 * _ZIG_X[i]
    return i, sgn, x


@numba.njit(cache=True, error_model="numpy")
def _normal_slow(r):  # pragma: no cover - numba
    """Standard normal of a word: the full ziggurat, more words chained by SplitMix64."""
    while True:
        i, sgn, x = _zig_candidate(r)
        if x < _ZIG_X[i + 1]:
            return sgn * x
        if i == 0:  # tail beyond R (Marsaglia 1964)
            while True:
                r = mix64(r + _GAMMA)
                xt = -math.log(1.0 - _uniform53(r)) / _ZIG_R
                r = mix64(r + _GAMMA)
                yt = -math.log(1.0 - _uniform53(r))
                if 2.0 * yt > xt * xt:
                    break
            return sgn * (_ZIG_R + xt)
        r = mix64(r + _GAMMA)  # wedge
        y = _ZIG_F[i] + _uniform53(r) * (_ZIG_F[i + 1] - _ZIG_F[i])
        if y < math.exp(-0.5 * x * x):
            return sgn * x
        r = mix64(r + _GAMMA)


@numba.njit(cache=True)
def _normals(key, n, out):  # pragma: no cover - numba
    """n standard normals from the kernel's ziggurat and words (tests the generator)."""
    for i in range(n):
        out[i] = _normal_slow(mix64(key + np.uint64(i + 1) * _GAMMA))


# --------------------------------------------------------------------------- smooth random fields
#
# A unit-variance Gaussian random field with autocorrelation close to exp(-(r / L)^2), made
# cheaply: white normals on a coarse grid (cell c ~ L / 2 px) are filtered by a separable
# Gaussian kernel, then interpolated bilinearly to the pixels. The kernel's width takes off
# what the interpolation adds (per axis, the autocorrelation's second moment L^2 / 2 is
# 2 s^2 from the kernel plus c^2 / 3 from the bilinear weights), and each pixel's weights
# are divided by the standard deviation of the interpolated value at its position within
# the cell, so the variance is 1 at every pixel. Rows are interpolated horizontally once per
# coarse row (``hrows``); a pixel row is then a blend of two of them.


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _field_block(key, kern, nx, j0, j1, iu, wu0, wu1):  # pragma: no cover - numba
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
            white[j] = _normal_slow(mix64(key + np.uint64(base + j + 1) * _GAMMA))
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
    return _field_block(key, kern, nx, 0, ny - 1, iu, wu0, wu1), rj, rw0, rw1


def _field_arg(key: np.uint64, h: int, w: int, length_px: float) -> tuple:
    """The kernel's field argument: each image block makes the coarse rows it needs."""
    ny, nx, kern, (iu, wu0, wu1), (rj, rw0, rw1) = _field_plan(h, w, float(length_px))
    return (True, key, kern, nx, iu, wu0, wu1, rj, rw0, rw1)


def smooth_field(seed: int, h: int, w: int, length_px: float) -> np.ndarray:
    """The h x w unit-variance random field of correlation length ``length_px`` (in image px)
    that a seed gives (float32): what the correlated terms add, before their scale."""
    hrows, rj, rw0, rw1 = _field_rows(_field_key(_seed_key(_check_seed(seed)), 1), h, w, length_px)
    return rw0[:, None] * hrows[rj] + rw1[:, None] * hrows[rj + 1]


def _field_key(key: np.uint64, tag: int) -> np.uint64:
    """Key of a field drawn from a frame or pattern key (tag 1: per-frame field, 2: pattern);
    unrelated to the per-pixel words of the same key."""
    return np.uint64(mix64_int(int(key) ^ (tag * 0xD1B54A32D192ED03)))


# --------------------------------------------------------------------------- kernels

_F32 = np.float32
# Abramowitz & Stegun 4.4.46: acos(x) = sqrt(1 - x) * poly(x), |error| <= 2e-8 on [0, 1].
_A0, _A1, _A2, _A3 = (
    _F32(1.5707963050),
    _F32(-0.2145988016),
    _F32(0.0889789874),
    _F32(-0.0501743046),
)
_A4, _A5, _A6, _A7 = (
    _F32(0.0308918810),
    _F32(-0.0170881256),
    _F32(0.0066700901),
    _F32(-0.0012624911),
)
_F0 = _F32(0.0)
_F1 = _F32(1.0)
_F2 = _F32(2.0)
_F_HALF = _F32(0.5)
_F_TINY = _F32(1e-30)
_F_TWO_M15 = _F32(2.0**-15)
_F_TWO_M16 = _F32(2.0**-16)
_U1 = np.uint32(1)
_U15 = np.uint32(0x7FFF)
_U16 = np.uint32(16)
_FINF = _F32(np.inf)
_F_HALF_PI = _F32(0.5 * math.pi)
_F_THETA_MAX = _F32(THETA_MAX_RAD)
_Q_MAX = float(_F_THETA_MAX / (_F_HALF_PI - _F_THETA_MAX))  # theta / (pi/2 - theta) at the clamp
# Vectorisable float maths that keeps NaN / inf semantics (no "nnan", "ninf").
_FAST = {"nsz", "arcp", "contract", "afn", "reassoc"}


@numba.njit(cache=True, inline="always", error_model="numpy", fastmath=_FAST)
def _acos01(c):  # pragma: no cover - numba
    """acos on [0, 1] (float32, A&S 4.4.46) without a libm call."""
    p = _A7
    p = p * c + _A6
    p = p * c + _A5
    p = p * c + _A4
    p = p * c + _A3
    p = p * c + _A2
    p = p * c + _A1
    p = p * c + _A0
    return math.sqrt(max(_F1 - c, _F0)) * p


@numba.njit(cache=True, inline="always", error_model="numpy", fastmath=_FAST)
def _theta_px(z, zl, zr, zu, zd, xl, xc, xr, yu, yc, yd, jump):  # pragma: no cover - numba
    """Incidence angle at one pixel from its 4 neighbours (0 = missing), branch free.

    With P = z (x, y, 1) the horizontal difference P_r - P_l is A r + alpha e_x, with
    r = (x_c, y_c, 1), A = z_r - z_l and alpha = (x_r - x_c) z_r + (x_c - x_l) z_l (a
    missing side is replaced by the centre: one-sided differences); likewise vertically
    B r + beta e_y. Their cross product is n = (-A beta, -alpha B, A beta x_c + alpha B y_c
    + alpha beta) and n . r = alpha beta, exactly.
    """
    lim = jump * z
    okl = (zl > _F0) & (abs(zl - z) <= lim)
    okr = (zr > _F0) & (abs(zr - z) <= lim)
    oku = (zu > _F0) & (abs(zu - z) <= lim)
    okd = (zd > _F0) & (abs(zd - z) <= lim)
    valid = (z > _F0) & (z < _FINF) & (okl | okr) & (oku | okd)
    zl = zl if okl else z
    zr = zr if okr else z
    zu = zu if oku else z
    zd = zd if okd else z
    al = (xc - xl) if okl else _F0
    ar = (xr - xc) if okr else _F0
    bu = (yc - yu) if oku else _F0
    bd = (yd - yc) if okd else _F0
    a = zr - zl
    alpha = ar * zr + al * zl
    b = zd - zu
    beta = bd * zd + bu * zu
    n1 = a * beta
    n2 = alpha * b
    ab = alpha * beta
    n3 = n1 * xc + n2 * yc + ab
    nn = (n1 * n1 + n2 * n2 + n3 * n3) * (xc * xc + yc * yc + _F1)
    c = min(abs(ab) / math.sqrt(nn), _F1)
    t = _acos01(c)
    return t if (valid & (nn > _F0)) else _F0


@numba.njit(cache=True, inline="always", error_model="numpy", fastmath=_FAST)
def _row_theta(depth, zero, v, xn, yn, jump, out):  # pragma: no cover - numba
    """Incidence angles of image row v into out (float32, vectorised)."""
    h, w = depth.shape
    rc = depth[v]
    ru = depth[v - 1] if v > 0 else zero
    rd = depth[v + 1] if v + 1 < h else zero
    yu = yn[v - 1] if v > 0 else _F0
    yd = yn[v + 1] if v + 1 < h else _F0
    yc = yn[v]
    if w == 1:
        out[0] = _theta_px(rc[0], _F0, _F0, ru[0], rd[0], _F0, xn[0], _F0, yu, yc, yd, jump)
        return
    for u in range(1, w - 1):
        out[u] = _theta_px(
            rc[u], rc[u - 1], rc[u + 1], ru[u], rd[u], xn[u - 1], xn[u], xn[u + 1], yu, yc, yd, jump
        )
    out[0] = _theta_px(rc[0], _F0, rc[1], ru[0], rd[0], _F0, xn[0], xn[1], yu, yc, yd, jump)
    e = w - 1
    out[e] = _theta_px(rc[e], rc[e - 1], _F0, ru[e], rd[e], xn[e - 1], xn[e], _F0, yu, yc, yd, jump)


@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
def _params_rows(
    depth, v0, v1, row0, xn, yn, jump, lat, sl, lit, th, theta_only
):  # pragma: no cover - numba
    """Incidence angles and lateral sigmas of rows [v0, v1) (float32, vectorised).

    theta (see :func:`incidence_angle`) comes from normals of the clean image; xn, yn are
    the float32 normalised pixel coordinates (u - cx) / fx, (v - cy) / fy. Writes the
    depth (0 where invalid) to lit, theta to th and sigma_L in image px to sl, with
    lat = (on, a, b, scale) (sigma_L = 0 when off). Image row v goes to row v - row0 of
    sl, lit, th. With theta_only, writes theta to sl and nothing else.
    """
    w = depth.shape[1]
    zero = np.zeros(w, dtype=np.float32)
    lon, la, lb, lsc = lat[0], lat[1], lat[2], lat[3]
    for v in range(v0, v1):
        slr = sl[v - row0]
        if theta_only:
            _row_theta(depth, zero, v, xn, yn, jump, slr)
            continue
        thr = th[v - row0]
        _row_theta(depth, zero, v, xn, yn, jump, thr)
        rc = depth[v]
        litr = lit[v - row0]
        for u in range(w):
            z = rc[u]
            litr[u] = z if (z > _F0) & (z < _FINF) else _F0  # lit until shadowed
            tc = min(thr[u], _F_THETA_MAX)
            slr[u] = lon * lsc * (la + lb * tc / (_F_HALF_PI - tc))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _shadow_rows(depth, v0, v1, row0, shift_px, lit):  # pragma: no cover - numba
    """Zero lit (the depth; image row v at v - row0) in rows [v0, v1) where the projector
    cannot see.

    shift_px = fx * projector_offset_m (signed, float32). The projector column of pixel u
    at depth z is u_p = u - shift_px / z (float32). Projector on the right (shift > 0):
    occluders lie to the right, so scan right to left keeping the running min of u_p; a
    pixel whose u_p is larger than that min is behind a nearer surface. Projector on the
    left: mirror image (scan left to right, running max). The shadow band lies on the side
    of a foreground object away from the projector.

    Only the stretch between the first and last "drop" (u_p[u] > u_p[u + 1]; invalid
    pixels count as infinitely far) needs the scan: beyond it u_p is monotone, so those
    pixels are visible (the scan stops once past it at a visible pixel).
    """
    w = depth.shape[1]
    if shift_px == _F0:
        return
    up = np.empty(w, dtype=np.float32)
    far = _FINF if shift_px > _F0 else -_FINF
    for v in range(v0, v1):
        rc = depth[v]
        for u in range(w):  # vectorised
            z = rc[u]
            up[u] = _F32(u) - shift_px / z if (z > _F0) & (z < _FINF) else far
        drops = 0
        for u in range(w - 1):  # vectorised
            drops += up[u] > up[u + 1]
        if drops == 0:
            continue
        first = 0
        while up[first] <= up[first + 1]:
            first += 1
        last = w - 2
        while up[last] <= up[last + 1]:
            last -= 1
        litr = lit[v - row0]
        if shift_px > _F0:
            run = up[last + 1]  # min of the non-decreasing part right of the last drop
            for u in range(last, -1, -1):
                x = up[u]
                if x <= run:
                    run = x
                    if u <= first:
                        break  # non-decreasing to the left: all visible
                else:
                    litr[u] = _F0
        else:
            run = up[first]  # max of the non-decreasing part left of the first drop
            for u in range(first + 1, w):
                x = up[u]
                if x >= run:
                    run = x
                    if u > last:
                        break  # non-decreasing to the right: all visible
                else:
                    litr[u] = _F0


@numba.njit(cache=True, inline="always", error_model="numpy")
def _split_sigma(sigma, aa, qz):  # pragma: no cover - numba
    """(per-pixel, correlated) parts of sigma_z, with a + qz its constant and range terms:
    the share qz^2 / (a^2 + qz^2) of sigma_z^2 is correlated, the rest is per pixel."""
    r = sigma / math.sqrt(aa * aa + qz * qz + _F_TINY)
    return r * aa, r * qz


@numba.njit(cache=True, inline="always", error_model="numpy")
def _pixel(z, ts, gzu, gfu, pu, udu, z0, prm, corr, pon):  # pragma: no cover - numba
    """Output depth of one pixel (step 5 of _noise_rows) from its source's lit depth z and
    incidence angle ts, its random numbers, field and pattern values and its own clean depth
    z0; corr and pon are constants at each call site, so the unused branches compile away."""
    aon, aa, ab, az0, ag, agst, don, dst, dinv, drate, quantize, fbs, zmin, zmax = prm
    tc = min(ts, _F_THETA_MAX)
    q = tc / (_F_HALF_PI - tc)
    graze = ag * q * q / math.sqrt(z) if tc > agst else _F0
    qz = ab * (z - az0) * (z - az0)
    sigma = aon * (aa + qz + graze)
    if corr:
        sw, sc = _split_sigma(sigma, aa, qz)
        zn = z + sw * gzu + sc * gfu
    else:
        zn = z + sigma * gzu
    if pon:
        dk = fbs / zn + pu
        zq = fbs / np.rint(dk) if quantize else fbs / dk
    else:
        k = np.rint(fbs / zn)
        zq = fbs / k if quantize else zn
    pg = don * min(max((ts - dst) * dinv, _F0), _F1)
    ok = (udu >= pg + drate - pg * drate) & (z0 > _F0) & (z0 < _FINF) & (z > _F0)
    ok = ok & (zq > _F0) & (zq < _FINF) & (zq >= zmin) & (zq <= zmax)
    return zq if ok else _F0


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _noise_rows(
    depth, v0, v1, row0, lit, th, sl, key, axl, drop, quantize, fbs, zmin, zmax, fld, pat, out
):  # pragma: no cover - numba
    """Lateral source, axial noise, quantisation, range cut and dropouts of rows [v0, v1).

    lit is the lit depth and th the incidence angle of every pixel, sl its sigma_L (image
    row v at v - row0; they must cover every row a lateral offset can reach).
    axl = (on, a, b, z0, c, theta_g): sigma_z = a + b (z - z0)^2 [+ c / sqrt(z) q^2 if
    theta > theta_g], q = theta / (pi/2 - theta), at the source pixel; drop = (on, start,
    1 / (full - start), rate). fbs = subpixel f b, zmin, zmax are float32 (zmax may be inf).
    fld = (on, hrows, j0, rj, rw0, rw1) is the per-frame correlated field (hrows holds coarse
    rows j0.. interpolated to the columns; see _field_rows) and
    pat = (on, image) the fixed pattern in 1/subpixel px of disparity, added before rounding.

    Per row, lean scalar loops (table lookups, gathers) and loops that LLVM vectorises
    (8 float32 lanes): 1 random word and table lookups (scalar); 2 lateral source index,
    ziggurat fast path, dropout uniform (vectorised); 3 the source's lit depth and theta
    (scalar gathers); 4 ziggurat slow paths (0.4 %); 5 sigma_z, noise, quantisation, range
    cut, dropouts (vectorised). Output pixels whose own input is invalid are 0.
    """
    h, w = depth.shape
    litf = lit.ravel()
    thf = th.ravel()
    prm = (axl[0], axl[1], axl[2], axl[3], axl[4], axl[5], drop[0], drop[1], drop[2], drop[3],
           quantize, fbs, zmin, zmax)  # fmt: skip
    corr, hrows, j0, rj, rw0, rw1 = fld
    pon, patim = pat
    gf = np.zeros(w, dtype=np.float32)  # stands in for the pattern's row when it is off
    hi = np.empty(w, dtype=np.uint32)  # bits 32-63 of the pixel's random word
    g1 = np.empty(w, dtype=np.float32)  # lateral normals
    g2 = np.empty(w, dtype=np.float32)
    x0 = np.empty(w, dtype=np.float32)  # ziggurat X[layer], X[layer + 1]
    x1 = np.empty(w, dtype=np.float32)
    src = np.empty(w, dtype=np.int32)  # flat source index
    gz = np.empty(w, dtype=np.float32)  # axial normal (0 where the slow path is pending)
    ud = np.empty(w, dtype=np.float32)  # dropout uniform
    slow = np.empty(w, dtype=np.bool_)
    zb = np.empty(w, dtype=np.float32)  # source's lit depth
    tb = np.empty(w, dtype=np.float32)  # source's incidence angle
    w32 = np.int32(w)
    r0 = np.int32(row0)
    wmax = np.int32(w - 1)
    hmax = np.int32(h - 1)
    for v in range(v0, v1):
        ctr = key + np.uint64(v * w) * _GAMMA
        for u in range(w):  # 1: scalar (table lookups)
            ctr += _GAMMA
            r = mix64(ctr)
            hi[u] = np.uint32(r >> _S32)
            g1[u] = _LAT_G[r & _LAT_MASK]
            g2[u] = _LAT_G[(r >> _S11) & _LAT_MASK]
            i = (r >> _S22) & _LAYER_MASK
            x0[u] = _ZIG_X32[i]
            x1[u] = _ZIG_X32[i + _ONE]
        slr = sl[v - row0]
        nslow = 0
        for u in range(w):  # 2: vectorised
            s = slr[u]
            us = min(max(np.int32(u + np.int32(np.rint(s * g1[u]))), np.int32(0)), wmax)
            vs = min(max(np.int32(v + np.int32(np.rint(s * g2[u]))), np.int32(0)), hmax)
            src[u] = np.int32((vs - r0) * w32 + us)
            b = hi[u]
            x = _F32(np.int32((b >> _U1) & _U15)) * _F_TWO_M15 * x0[u]
            fast = x < x1[u]
            sgn = _F1 - _F2 * _F32(np.int32(b & _U1))
            gz[u] = sgn * x if fast else _F0
            ud[u] = (_F32(np.int32(b >> _U16)) + _F_HALF) * _F_TWO_M16
            slow[u] = not fast
            nslow += not fast
        for u in range(w):  # 3: scalar (gathers)
            j = np.uint64(src[u])
            zb[u] = litf[j]
            tb[u] = thf[j]
        if nslow > 0:  # 4: the ziggurat's slow paths
            ctr = key + np.uint64(v * w) * _GAMMA
            for u in range(w):
                if slow[u]:
                    gz[u] = _F32(_normal_slow(mix64(ctr + np.uint64(u + 1) * _GAMMA)))
        rc = depth[v]
        orow = out[v]
        j = rj[v] - j0 if corr else 0
        h0 = hrows[j]  # the correlated field on this row: c0 h0 + c1 h1
        h1 = hrows[j + 1]
        c0 = rw0[v]
        c1 = rw1[v]
        prow = patim[v] if pon else gf
        # 5: vectorised; one loop per combination of the terms, so each is branch free
        if corr and pon:
            for u in range(w):
                g = c0 * h0[u] + c1 * h1[u]
                orow[u] = _pixel(zb[u], tb[u], gz[u], g, prow[u], ud[u], rc[u], prm, True, True)
        elif corr:
            for u in range(w):
                g = c0 * h0[u] + c1 * h1[u]
                orow[u] = _pixel(zb[u], tb[u], gz[u], g, _F0, ud[u], rc[u], prm, True, False)
        elif pon:
            for u in range(w):
                orow[u] = _pixel(zb[u], tb[u], gz[u], _F0, prow[u], ud[u], rc[u], prm, False, True)
        else:
            for u in range(w):
                orow[u] = _pixel(zb[u], tb[u], gz[u], _F0, _F0, ud[u], rc[u], prm, False, False)


@numba.njit(cache=True, nogil=True)
def _block(
    depth,
    r0,
    r1,
    margin,
    xn,
    yn,
    jump,
    lat,
    shift_px,
    key,
    axl,
    drop,
    quantize,
    fbs,
    zmin,
    zmax,
    fld,
    pat,
    sl,
    lit,
    th,
    out,
    theta_only,
):  # pragma: no cover - numba
    """The whole model for output rows [r0, r1): parameters and shadows of rows
    [r0 - margin, r1 + margin) into the block's own scratch (sl, lit, th), then the noise.

    margin bounds the lateral row offsets, so blocks are independent (their halo rows are
    computed twice, identically) and can run concurrently. With theta_only, just the
    incidence angles of rows [r0, r1), into sl.
    """
    h = depth.shape[0]
    a0 = max(0, r0 - margin)
    a1 = min(h, r1 + margin)
    if theta_only:
        _params_rows(depth, r0, r1, r0, xn, yn, jump, lat, sl, lit, th, True)
        return
    _params_rows(depth, a0, a1, a0, xn, yn, jump, lat, sl, lit, th, False)
    _shadow_rows(depth, a0, a1, a0, shift_px, lit)
    corr, fkey, kern, nx, iu, wu0, wu1, rj, rw0, rw1 = fld
    j0 = rj[r0] if r1 > r0 else 0
    j1 = rj[r1 - 1] + 1 if (corr and r1 > r0) else j0 + 1
    hrows = _field_block(fkey, kern, nx, j0, j1, iu, wu0, wu1) if corr else np.zeros((2, iu.size), np.float32)
    rows = (corr, hrows, j0, rj, rw0, rw1)
    _noise_rows(
        depth, r0, r1, a0, lit, th, sl, key, axl, drop, quantize, fbs, zmin, zmax, rows, pat, out
    )


# --------------------------------------------------------------------------- public API


def _check_depth(depth, intr: CameraIntrinsics) -> np.ndarray:
    if not isinstance(intr, CameraIntrinsics):
        raise InputError(f"intrinsics: expected CameraIntrinsics, got {type(intr).__name__}")
    arr = np.asarray(depth)
    if arr.dtype.kind != "f":
        raise InputError(f"depth image: expected a float array in metres, got dtype {arr.dtype}")
    if arr.shape != (intr.height, intr.width):
        raise InputError(
            f"depth image shape {arr.shape} does not match the camera's {(intr.height, intr.width)}"
        )
    return np.ascontiguousarray(arr, dtype=np.float32)


@functools.lru_cache(maxsize=8)
def _normalised_coords(intr: CameraIntrinsics) -> tuple[np.ndarray, np.ndarray]:
    """float32 (u - cx) / fx and (v - cy) / fy (cached per camera; read-only)."""
    xn = ((np.arange(intr.width, dtype=np.float64) - intr.cx) / intr.fx).astype(np.float32)
    yn = ((np.arange(intr.height, dtype=np.float64) - intr.cy) / intr.fy).astype(np.float32)
    xn.setflags(write=False)
    yn.setflags(write=False)
    return xn, yn


def incidence_angle(
    depth: np.ndarray, intr: CameraIntrinsics, max_rel_jump: float = 0.05
) -> np.ndarray:
    """Angle between each pixel's ray and its surface normal (float32 radians, H x W).

    Normals are the cross product of horizontal and vertical differences of back-projected
    neighbours (central; one-sided at borders, invalid neighbours and depth jumps larger
    than ``max_rel_jump * z``). Pixels without a normal (or invalid) get 0.
    """
    d = _check_depth(depth, intr)
    if not (isinstance(max_rel_jump, int | float) and max_rel_jump > 0):
        raise InputError(f"incidence_angle: max_rel_jump must be > 0, got {max_rel_jump!r}")
    xn, yn = _normalised_coords(intr)
    theta = np.empty(d.shape, dtype=np.float32)
    lat, axl, drop = _cfg_arrays(KinectNoiseConfig(), intr)
    t = theta
    f0 = np.float32(0)
    _block(
        d, 0, d.shape[0], 0, xn, yn, np.float32(max_rel_jump), lat, f0, np.uint64(0), axl,
        drop, False, f0, f0, f0, _no_field(d.shape), _no_pattern(), t, t, t, t, True,
    )  # fmt: skip
    return theta


def _fbs(cfg: KinectNoiseConfig) -> float:
    """subpixel * focal_px * baseline_m: depth times disparity in 1/subpixel px units."""
    return float(cfg.subpixel) * float(cfg.focal_px) * float(cfg.baseline_m)


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise InputError(f"seed: expected an int, got {seed!r}")
    seed = int(seed)
    if not 0 <= seed < 2**64:
        raise InputError(f"seed: must be in [0, 2**64), got {seed}")
    return seed


def _seed_key(seed: int) -> np.uint64:
    """Per-frame key: SplitMix64 of the seed (nearby seeds give unrelated streams)."""
    return np.uint64(mix64_int(seed * GAMMA + 0x632BE59BD9B4E019))


_CPUS = os.cpu_count() or 1  # read once: the call costs tens of microseconds here
_tls = threading.local()
_pool_lock = threading.Lock()
_workers: list[queue.SimpleQueue] = []  # one task queue per worker thread


def _reset_pool() -> None:
    global _workers
    _workers = []


def _worker(tasks: queue.SimpleQueue) -> None:
    """A block worker: runs (call, done) tasks, reporting None or the exception to done."""
    while True:
        call, done = tasks.get()
        try:
            _block(*call)
            done.put(None)
        except BaseException as exc:  # handed to the caller, which raises it
            done.put(exc)


os.register_at_fork(after_in_child=_reset_pool)  # a forked child has no pool threads


def _scratch(block: int, rows: int, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-thread, per-block scratch images (sigma_L, lit depth, theta), reused across frames."""
    cache = getattr(_tls, "scratch", None)
    if cache is None:
        cache = _tls.scratch = {}
    ws = cache.get(block)
    if ws is None or ws[0].shape[0] < rows or ws[0].shape[1] != w:
        ws = cache[block] = tuple(np.zeros((rows, w), dtype=np.float32) for _ in range(3))
    return ws


def _run_blocks(n: int, depth: np.ndarray, margin: int, args: tuple, out: np.ndarray) -> None:
    """_block over all rows split into n blocks, blocks 1.. on pool threads (GIL released).

    Every row's result depends only on the inputs and the seed, so the output is the same
    for any n.
    """
    h, w = depth.shape
    bounds = [h * c // n for c in range(n + 1)]
    calls = []
    for c in range(n):
        r0, r1 = bounds[c], bounds[c + 1]
        sl, lit, th = _scratch(c, min(h, r1 - r0 + 2 * margin), w)
        calls.append((depth, r0, r1, margin, *args, sl, lit, th, out, False))
    if n == 1:
        _block(*calls[0])
        return
    with _pool_lock:
        while len(_workers) < n - 1:
            tasks: queue.SimpleQueue = queue.SimpleQueue()
            name = f"kinect_noise_{len(_workers)}"
            threading.Thread(target=_worker, args=(tasks,), name=name, daemon=True).start()
            _workers.append(tasks)
        workers = _workers[: n - 1]
    # A plain queue hand-off: a thread pool's futures cost tens of microseconds a frame.
    done: queue.SimpleQueue = queue.SimpleQueue()
    for tasks, call in zip(workers, calls[1:], strict=True):
        tasks.put((call, done))
    _block(*calls[0])
    errors = [done.get() for _ in workers]
    for exc in errors:
        if exc is not None:
            raise exc


@functools.lru_cache(maxsize=8)
def _no_field(shape: tuple[int, int]) -> tuple:
    """The kernel's field argument when the correlated term is off (cached; never written)."""
    ny, nx, kern, (iu, wu0, wu1), (rj, rw0, rw1) = _field_plan(shape[0], shape[1], 2.0)
    return (False, np.uint64(0), kern, nx, iu, wu0, wu1, rj, rw0, rw1)


_EMPTY_PATTERN = np.zeros((1, 1), dtype=np.float32)
_EMPTY_PATTERN.setflags(write=False)  # the same array type as a pattern image


def _no_pattern() -> tuple:
    """The kernel's pattern argument when the fixed pattern is off."""
    return (False, _EMPTY_PATTERN)


def _pattern_on(cfg: KinectNoiseConfig) -> bool:
    return bool(cfg.pattern and cfg.pattern_sigma_px > 0)


_pattern_lock = threading.Lock()
_patterns: dict[tuple, np.ndarray] = {}


def _pattern_image(cfg: KinectNoiseConfig, h: int, w: int, scale: float) -> np.ndarray:
    """The fixed pattern of ``cfg.pattern_seed`` in 1/subpixel px of disparity of the
    focal_px camera, the kernel's unit (h x w, float32, read-only), made once per sensor and
    image geometry and then reused; ``scale`` turns its correlation length into image px."""
    k = (cfg.pattern_seed, h, w, float(cfg.pattern_length_px * scale),
         float(cfg.pattern_sigma_px * cfg.subpixel))  # fmt: skip
    with _pattern_lock:
        img = _patterns.get(k)
        if img is None:
            hrows, rj, rw0, rw1 = _field_rows(_field_key(_seed_key(k[0]), 2), h, w, k[3])
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
    if not _pattern_on(cfg):
        return np.zeros((intr.height, intr.width), dtype=np.float32)
    scale = intr.fx / cfg.focal_px
    return _pattern_image(cfg, intr.height, intr.width, scale) / np.float32(cfg.subpixel)


@functools.lru_cache(maxsize=32)
def _cfg_arrays(cfg: KinectNoiseConfig, intr: CameraIntrinsics) -> tuple[np.ndarray, ...]:
    f32 = np.float32
    lat = np.array(
        [cfg.lateral, cfg.lateral_a_px, cfg.lateral_b_px, intr.fx / cfg.focal_px], dtype=f32
    )
    axl = np.array(
        [cfg.axial, cfg.axial_a_m, cfg.axial_b_per_m, cfg.axial_z0_m, cfg.axial_grazing_m,
         cfg.axial_grazing_start_rad],
        dtype=f32,
    )  # fmt: skip
    drop = np.array(
        [cfg.dropouts, cfg.dropout_start_rad, 1.0 / (cfg.dropout_full_rad - cfg.dropout_start_rad),
         cfg.dropout_rate if cfg.dropouts else 0.0],
        dtype=f32,
    )  # fmt: skip
    return lat, axl, drop


def apply_kinect_noise(
    depth: np.ndarray,
    intr: CameraIntrinsics,
    cfg: KinectNoiseConfig,
    seed: int,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """The noisy Kinect v1 depth image (float32 metres, 0 = invalid) for a clean planar depth.

    ``out`` (float32, C-contiguous, H x W) is filled and returned if given; it may be the
    input array itself. Same seed -> identical output. Pixels invalid in the input (0,
    negative, NaN, inf) are 0 in the output.
    """
    d = _check_depth(depth, intr)
    if not isinstance(cfg, KinectNoiseConfig):
        raise InputError(f"cfg: expected KinectNoiseConfig, got {type(cfg).__name__}")
    key = _seed_key(_check_seed(seed))
    if out is None:
        out = np.empty(d.shape, dtype=np.float32)
    elif not (
        isinstance(out, np.ndarray)
        and out.dtype == np.float32
        and out.shape == d.shape
        and out.flags.c_contiguous
        and out.flags.writeable
    ):
        raise InputError(f"out: expected a writeable C-contiguous float32 array of shape {d.shape}")
    if np.shares_memory(d, out):
        d = d.copy()
    xn, yn = _normalised_coords(intr)
    lat, axl, drop = _cfg_arrays(cfg, intr)
    # bound on |lateral row offset|: the largest table normal times the largest sigma_L
    sigma_max = float(lat[0]) * float(lat[3]) * (float(lat[1]) + float(lat[2]) * _Q_MAX)
    margin = math.ceil(_LAT_G_MAX * sigma_max) + 1
    n = max(1, min(cfg.threads, _CPUS, d.shape[0]))
    h, w = d.shape
    scale = intr.fx / cfg.focal_px  # correlation lengths are in px of the focal_px camera
    if cfg.correlated and cfg.axial:
        fld = _field_arg(_field_key(key, 1), h, w, cfg.corr_length_px * scale)
    else:
        fld = _no_field(d.shape)
    pat = (True, _pattern_image(cfg, h, w, scale)) if _pattern_on(cfg) else _no_pattern()
    args = (
        xn, yn, np.float32(cfg.normal_max_rel_jump), lat,
        np.float32(intr.fx * cfg.projector_offset_m if cfg.shadows else 0.0), key, axl, drop,
        bool(cfg.quantize), np.float32(_fbs(cfg)), np.float32(cfg.min_range_m),
        np.float32(cfg.max_range_m), fld, pat,
    )  # fmt: skip
    _run_blocks(n, d, margin, args, out)
    return out
