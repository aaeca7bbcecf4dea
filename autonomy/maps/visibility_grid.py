"""The visibility grid of a vector map (BV2012, Sec. IV-A: visibility precomputed per cell).

:class:`VisibilityGrid` stores, per cell of a regular grid, the walls that can be seen
from some point of the cell within ``max_range_m`` (conservatively: every wall whose
distance to the cell's box is at most the range), so a query only looks at a few hundred
walls of a 10,000-wall map. :func:`load_or_build` caches a grid on disk as
``<map file>.visgrid.npz`` (or in ``~/.cache/depthnav``), keyed by a hash of the walls and the config.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

from autonomy.common.cache import cache_paths
from autonomy.common.errors import InputError
from autonomy.common.files import atomic_write
from autonomy.maps.analytic_raycast import _scene_lines_kernel
from autonomy.maps.vectormap import VectorMap

__all__ = ["VisibilityGridConfig", "VisibilityGrid", "load_or_build"]

_GRID_VERSION = 2
"""Bumped whenever the cache file layout or the candidate rule changes."""


@dataclass(frozen=True)
class VisibilityGridConfig:
    """Visibility grid parameters (ours: the paper precomputes visibility without details)."""

    cell_m: float = 0.5
    """Cell size in metres."""
    max_range_m: float = 8.0
    """Walls farther than this from every point of a cell are not candidates (sensor range)."""

    def __post_init__(self) -> None:
        for name in ("cell_m", "max_range_m"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise InputError(f"VisibilityGridConfig.{name}: expected a positive number, got {v!r}")


@numba.njit(cache=True, inline="always")
def _pt_seg_d2(px: float, py: float, ax: float, ay: float, bx: float, by: float) -> float:
    ex = bx - ax
    ey = by - ay
    l2 = ex * ex + ey * ey
    t = 0.0
    if l2 > 0.0:
        t = ((px - ax) * ex + (py - ay) * ey) / l2
        if t < 0.0:
            t = 0.0
        elif t > 1.0:
            t = 1.0
    qx = ax + t * ex - px
    qy = ay + t * ey - py
    return qx * qx + qy * qy


@numba.njit(cache=True, inline="always")
def _pt_box_d2(px: float, py: float, x0: float, y0: float, x1: float, y1: float) -> float:
    dx = 0.0
    if px < x0:
        dx = x0 - px
    elif px > x1:
        dx = px - x1
    dy = 0.0
    if py < y0:
        dy = y0 - py
    elif py > y1:
        dy = py - y1
    return dx * dx + dy * dy


@numba.njit(cache=True)
def _seg_box_d2(
    ax: float, ay: float, bx: float, by: float, x0: float, y0: float, x1: float, y1: float
) -> float:
    """Squared distance between segment A-B and the box [x0, x1] x [y0, y1]."""
    # Liang-Barsky: does the segment meet the box?
    ex = bx - ax
    ey = by - ay
    lo = 0.0
    hi = 1.0
    meets = True
    for p, q in ((-ex, ax - x0), (ex, x1 - ax), (-ey, ay - y0), (ey, y1 - ay)):
        if p == 0.0:
            if q < 0.0:
                meets = False
                break
        else:
            t = q / p
            if p < 0.0:
                if t > lo:
                    lo = t
            elif t < hi:
                hi = t
            if lo > hi:
                meets = False
                break
    if meets:
        return 0.0
    d = min(_pt_box_d2(ax, ay, x0, y0, x1, y1), _pt_box_d2(bx, by, x0, y0, x1, y1))
    d = min(d, _pt_seg_d2(x0, y0, ax, ay, bx, by))
    d = min(d, _pt_seg_d2(x1, y0, ax, ay, bx, by))
    d = min(d, _pt_seg_d2(x0, y1, ax, ay, bx, by))
    d = min(d, _pt_seg_d2(x1, y1, ax, ay, bx, by))
    return d


@numba.njit(cache=True)
def _grid_pass(
    segments: np.ndarray,
    x0: float,
    y0: float,
    cell: float,
    nx: int,
    ny: int,
    rng: float,
    counts: np.ndarray,
    indices: np.ndarray,
    fill: bool,
) -> None:
    """One pass over the segments: count (``fill`` False) or store (True) cell members."""
    r2 = rng * rng
    for i in range(segments.shape[0]):
        ax = segments[i, 0]
        ay = segments[i, 1]
        bx = segments[i, 2]
        by = segments[i, 3]
        ix0 = max(0, int(math.floor((min(ax, bx) - rng - x0) / cell)))
        ix1 = min(nx - 1, int(math.floor((max(ax, bx) + rng - x0) / cell)))
        iy0 = max(0, int(math.floor((min(ay, by) - rng - y0) / cell)))
        iy1 = min(ny - 1, int(math.floor((max(ay, by) + rng - y0) / cell)))
        for iy in range(iy0, iy1 + 1):
            cy0 = y0 + iy * cell
            for ix in range(ix0, ix1 + 1):
                cx0 = x0 + ix * cell
                if _seg_box_d2(ax, ay, bx, by, cx0, cy0, cx0 + cell, cy0 + cell) <= r2:
                    c = iy * nx + ix
                    if fill:
                        indices[counts[c]] = i
                    counts[c] += 1


@numba.njit(cache=True)
def _build_grid_kernel(
    segments: np.ndarray, x0: float, y0: float, cell: float, nx: int, ny: int, rng: float
) -> tuple[np.ndarray, np.ndarray]:
    """CSR (offsets, indices) of the segments within ``rng`` of each cell's box."""
    ncell = nx * ny
    counts = np.zeros(ncell, np.int64)
    indices = np.empty(0, np.int32)
    _grid_pass(segments, x0, y0, cell, nx, ny, rng, counts, indices, False)
    offsets = np.empty(ncell + 1, np.int64)
    offsets[0] = 0
    for c in range(ncell):
        offsets[c + 1] = offsets[c] + counts[c]
    indices = np.empty(offsets[ncell], np.int32)
    fillpos = offsets[:ncell].copy()
    _grid_pass(segments, x0, y0, cell, nx, ny, rng, fillpos, indices, True)
    return offsets, indices


@numba.njit(cache=True)
def _near_point(segments: np.ndarray, x: float, y: float, rng: float) -> np.ndarray:
    """Indices of the segments within ``rng`` of (x, y) (grid fallback)."""
    r2 = rng * rng
    out = np.empty(segments.shape[0], np.int32)
    k = 0
    for i in range(segments.shape[0]):
        if _pt_seg_d2(x, y, segments[i, 0], segments[i, 1], segments[i, 2], segments[i, 3]) <= r2:
            out[k] = i
            k += 1
    return out[:k]


@numba.njit(cache=True)
def _query_kernel(
    segments: np.ndarray,
    offsets: np.ndarray,
    indices: np.ndarray,
    x0: float,
    y0: float,
    cell: float,
    nx: int,
    ny: int,
    rng: float,
    x: float,
    y: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Grid lookup + Algorithm 2 clipped to ``rng`` in one call (no Python in between)."""
    fx = (x - x0) / cell
    fy = (y - y0) / cell
    if 0.0 <= fx <= nx and 0.0 <= fy <= ny:
        ix = min(int(fx), nx - 1)
        iy = min(int(fy), ny - 1)
        c = iy * nx + ix
        cand = indices[offsets[c] : offsets[c + 1]]
    else:
        cand = _near_point(segments, x, y, rng)
    return _scene_lines_kernel(segments, cand.astype(np.int64), x, y, rng)


def _segments_hash(segments: np.ndarray) -> str:
    seg = np.ascontiguousarray(segments, dtype=np.float64)
    h = hashlib.sha256()
    h.update(str(seg.shape).encode())
    h.update(seg.tobytes())
    return h.hexdigest()


def _grid_key(segments: np.ndarray, cfg: VisibilityGridConfig) -> str:
    h = hashlib.sha256()
    h.update(f"depthnav-visgrid-v{_GRID_VERSION}|{cfg.cell_m!r}|{cfg.max_range_m!r}|".encode())
    h.update(_segments_hash(segments).encode())
    return h.hexdigest()


@dataclass(frozen=True, eq=False)
class VisibilityGrid:
    """Per-cell candidate walls for :func:`scene_lines`, in CSR form.

    Cell ``(ix, iy)`` covers ``[x0 + ix c, x0 + (ix + 1) c) x [y0 + iy c, ...)`` and has flat
    index ``iy * nx + ix``; its candidates are ``indices[offsets[k]:offsets[k + 1]]``, the
    (ascending) indices of the walls whose distance to the cell's box is at most
    ``config.max_range_m`` — every wall visible from the cell within that range.
    """

    offsets: np.ndarray
    """(nx * ny + 1,) int64 CSR offsets."""
    indices: np.ndarray
    """(nnz,) int32 segment indices."""
    origin: tuple[float, float]
    """(x0, y0): lower-left corner of cell (0, 0), metres."""
    shape: tuple[int, int]
    """(ny, nx): rows (y) and columns (x) of cells."""
    config: VisibilityGridConfig
    """Cell size and range the grid was built with."""
    segments: np.ndarray
    """(N, 4) read-only walls of the map the grid was built for (for the fallback)."""
    key: str
    """Hash of the map's segments and the config (cache key)."""

    @property
    def n_segments(self) -> int:
        """Number of walls of the map the grid was built for."""
        return int(self.segments.shape[0])

    @property
    def nx(self) -> int:
        """Cells along x."""
        return self.shape[1]

    @property
    def ny(self) -> int:
        """Cells along y."""
        return self.shape[0]

    @property
    def counts(self) -> np.ndarray:
        """(ny, nx) number of candidates per cell."""
        return np.diff(self.offsets).reshape(self.shape)

    @classmethod
    def build(cls, vm: VectorMap, cfg: VisibilityGridConfig = VisibilityGridConfig()) -> VisibilityGrid:  # noqa: B008
        """Grid over the map's extent; candidates by segment-to-cell-box distance (numba)."""
        if vm.n_segments == 0:
            raise InputError(f"vector map {vm.name!r} has no segments: no visibility grid")
        xmin, ymin, xmax, ymax = vm.extent()
        c = float(cfg.cell_m)
        nx = max(1, math.ceil((xmax - xmin) / c))
        ny = max(1, math.ceil((ymax - ymin) / c))
        if nx * ny > 50_000_000:
            raise InputError(f"visibility grid of {nx} x {ny} cells is too large; use a larger cell_m than {c}")
        offsets, indices = _build_grid_kernel(vm.segments, xmin, ymin, c, nx, ny, float(cfg.max_range_m))
        return cls(
            offsets=offsets,
            indices=indices,
            origin=(float(xmin), float(ymin)),
            shape=(int(ny), int(nx)),
            config=cfg,
            segments=vm.segments,
            key=_grid_key(vm.segments, cfg),
        )

    def cell_of(self, x: float, y: float) -> int:
        """Flat index of the cell containing (x, y), or -1 outside the grid."""
        fx = (x - self.origin[0]) / self.config.cell_m
        fy = (y - self.origin[1]) / self.config.cell_m
        if not (0.0 <= fx <= self.nx and 0.0 <= fy <= self.ny):
            return -1
        return min(int(fy), self.ny - 1) * self.nx + min(int(fx), self.nx - 1)

    def candidates(self, x: float, y: float) -> np.ndarray:
        """int64 indices of the walls that can be visible from the cell of (x, y) within range;
        outside the grid, those within ``max_range_m`` of the point itself."""
        c = self.cell_of(x, y)
        if c >= 0:
            return self.indices[self.offsets[c] : self.offsets[c + 1]].astype(np.int64)
        return _near_point(self.segments, float(x), float(y), float(self.config.max_range_m)).astype(np.int64)

    # ---- files

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the grid to ``path`` (an ``.npz``; written atomically)."""
        p = Path(path)
        arrays = {
            "version": np.array(_GRID_VERSION),
            "offsets": self.offsets,
            "indices": self.indices,
            "origin": np.array(self.origin, dtype=np.float64),
            "shape": np.array(self.shape, dtype=np.int64),
            "cell_m": np.array(self.config.cell_m, dtype=np.float64),
            "max_range_m": np.array(self.config.max_range_m, dtype=np.float64),
            "segments": self.segments,
            "key": np.array(self.key),
        }
        try:
            return atomic_write(p, lambda f: np.savez_compressed(f, **arrays))
        except OSError as e:
            raise InputError(f"{p}: cannot write visibility grid ({e.strerror or e})") from None

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> VisibilityGrid:
        """Read a grid written by :meth:`save`; a missing or malformed file is an InputError."""
        p = Path(path)
        try:
            with np.load(p, allow_pickle=False) as z:
                version = int(z["version"])
                if version != _GRID_VERSION:
                    raise InputError(f"{p}: visibility grid version {version}, expected {_GRID_VERSION}")
                offsets = np.ascontiguousarray(z["offsets"], dtype=np.int64)
                indices = np.ascontiguousarray(z["indices"], dtype=np.int32)
                origin = tuple(float(v) for v in z["origin"])
                shape = tuple(int(v) for v in z["shape"])
                cfg = VisibilityGridConfig(float(z["cell_m"]), float(z["max_range_m"]))
                seg = np.ascontiguousarray(z["segments"], dtype=np.float64)
                key = str(z["key"])
        except InputError:
            raise
        except FileNotFoundError:
            raise InputError(f"{p}: file not found") from None
        except Exception as e:  # zip, zlib, npy header, missing key ...
            raise InputError(f"{p}: not a visibility grid file ({type(e).__name__}: {e})") from None
        if len(origin) != 2 or len(shape) != 2 or min(shape) < 1:
            raise InputError(f"{p}: bad visibility grid origin/shape {origin} {shape}")
        if seg.ndim != 2 or seg.shape[1] != 4 or _grid_key(seg, cfg) != key:
            raise InputError(f"{p}: visibility grid key does not match its segments and config")
        n_seg = seg.shape[0]
        ncell = shape[0] * shape[1]
        if (
            offsets.shape != (ncell + 1,)
            or offsets[0] != 0
            or offsets[-1] != indices.shape[0]
            or np.any(np.diff(offsets) < 0)
            or (indices.size and (indices.min() < 0 or indices.max() >= n_seg))
        ):
            raise InputError(f"{p}: inconsistent visibility grid arrays")
        seg.setflags(write=False)
        return cls(offsets, indices, origin, shape, cfg, seg, key)  # type: ignore[arg-type]


def load_or_build(
    vm: VectorMap,
    map_path: str | os.PathLike[str] | None,
    cfg: VisibilityGridConfig = VisibilityGridConfig(),  # noqa: B008
) -> VisibilityGrid:
    """The grid of ``vm``, cached as ``<map file>.visgrid.npz`` (or under ``~/.cache/depthnav``
    when that directory is not writable or there is no map file).

    The cache is keyed by a hash of the segments and the config: a stale, foreign or
    corrupt cache file is rebuilt and overwritten, never an error.
    """
    key = _grid_key(vm.segments, cfg)
    paths = cache_paths(map_path, key, ".visgrid.npz")
    for p in paths:
        if not p.is_file():
            continue
        try:
            g = VisibilityGrid.load(p)
        except InputError:
            continue
        if g.key == key and g.config == cfg and np.array_equal(g.segments, vm.segments):
            return g
    g = VisibilityGrid.build(vm, cfg)
    for p in cache_paths(map_path, key, ".visgrid.npz", for_writing=True):
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            g.save(p)
            break
        except (OSError, InputError):
            continue
    return g
