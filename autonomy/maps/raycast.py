"""Analytic ray casting on a vector map: scene lines and the visibility grid (BV2012, Sec. IV-A).

:func:`scene_lines` is Algorithm 2 ("AnalyticRayCast"); its readings and tolerances are
described in :mod:`autonomy.maps.analytic_raycast`.

:class:`VisibilityGrid` stores, per cell of a regular grid, the walls that can be seen
from some point of the cell within ``max_range_m`` (conservatively: every wall whose
distance to the cell's box is at most the range), so a query only looks at a few hundred
walls of a 10,000-wall map. :class:`SceneQuery` bundles a map and its grid; its scene lines
are clipped to the disk of radius ``max_range_m`` around x, which makes them identical to
the clipped scene lines of the whole map. :func:`load_or_build` caches a grid on disk as
``<map file>.visgrid.npz`` (or in ``~/.cache/depthnav``), keyed by a hash of the walls and
the config.

:func:`ray_hit` / :func:`rays_hit` intersect rays with a set of lines (e.g. scene lines).

The pieces live in sibling modules, re-exported here: Algorithm 2 in
:mod:`autonomy.maps.analytic_raycast`, the grid and its cache in
:mod:`autonomy.maps.visibility_grid`, ray hits in :mod:`autonomy.maps.ray_hits`; this
module holds :class:`SceneQuery` and the benchmark.
"""


from __future__ import annotations

import time

import numpy as np

from autonomy.common.errors import InputError
from autonomy.maps.analytic_raycast import MIN_PIECE_M, scene_lines
from autonomy.maps.ray_hits import bearing_index, ray_hit, ray_hit_indexed, ray_hit_nb, rays_hit
from autonomy.maps.vectormap import VectorMap
from autonomy.maps.visibility_grid import (
    VisibilityGrid,
    VisibilityGridConfig,
    _query_kernel,
    load_or_build,
)

__all__ = [
    "scene_lines",
    "ray_hit",
    "rays_hit",
    "ray_hit_nb",
    "bearing_index",
    "ray_hit_indexed",
    "VisibilityGridConfig",
    "VisibilityGrid",
    "SceneQuery",
    "load_or_build",
    "benchmark_scene_lines",
    "MIN_PIECE_M",
]


# --------------------------------------------------------------------------- SceneQuery


class SceneQuery:
    """A map plus its visibility grid: scene lines for any location (BV2012, Sec. IV-A).

    Scene lines are clipped to the disk of ``grid.config.max_range_m`` around the
    location; within that disk they equal :func:`scene_lines` over the whole map.
    """

    def __init__(self, vm: VectorMap, grid: VisibilityGrid | None = None) -> None:
        if grid is None:
            grid = VisibilityGrid.build(vm)
        elif grid.segments.shape != vm.segments.shape or not np.array_equal(grid.segments, vm.segments):
            raise InputError(f"visibility grid was built for another map than {vm.name!r}")
        self.vm = vm
        self.grid = grid
        self._seg = vm.segments
        self._args = (
            grid.offsets,
            grid.indices,
            float(grid.origin[0]),
            float(grid.origin[1]),
            float(grid.config.cell_m),
            int(grid.nx),
            int(grid.ny),
            float(grid.config.max_range_m),
        )

    @property
    def max_range_m(self) -> float:
        """Range the scene lines are clipped to."""
        return float(self.grid.config.max_range_m)

    def candidates(self, x: float, y: float) -> np.ndarray:
        """int64 candidate wall indices for (x, y) (see :meth:`VisibilityGrid.candidates`)."""
        return self.grid.candidates(x, y)

    def scene_lines(self, x: float, y: float) -> tuple[np.ndarray, np.ndarray]:
        """``(lines (M, 4), source (M,) int64)`` seen from (x, y), as :func:`scene_lines`."""
        return _query_kernel(self._seg, *self._args, float(x), float(y))


# --------------------------------------------------------------------------- benchmark


def _free_points(vm: VectorMap, n: int, rng: np.random.Generator, clearance_m: float = 0.3) -> np.ndarray:
    """``n`` uniform points in the map's extent at least ``clearance_m`` from every wall."""
    xmin, ymin, xmax, ymax = vm.extent()
    seg = vm.segments
    out: list[np.ndarray] = []
    have = 0
    while have < n:
        p = rng.uniform((xmin, ymin), (xmax, ymax), size=(max(64, n), 2))
        a = seg[None, :, 0:2]
        e = seg[None, :, 2:4] - a
        ok = np.ones(len(p), dtype=bool)
        for s in range(0, len(p), 64):
            q = p[s : s + 64, None, :]
            t = np.clip(((q - a) * e).sum(-1) / (e * e).sum(-1), 0.0, 1.0)
            d = np.hypot(*np.moveaxis(a + t[..., None] * e - q, -1, 0)).min(axis=1)
            ok[s : s + 64] = d >= clearance_m
        out.append(p[ok])
        have += int(ok.sum())
    return np.concatenate(out)[:n]


def benchmark_scene_lines(
    vm: VectorMap, n: int = 1000, *, seed: int = 0, grid: VisibilityGrid | None = None
) -> float:
    """Median microseconds of one :meth:`SceneQuery.scene_lines` call at ``n`` random free
    locations (>= 0.3 m from any wall) of ``vm``, grid included, JIT warmed up."""
    q = SceneQuery(vm, grid)
    pts = _free_points(vm, n, np.random.default_rng(seed))
    for p in pts[:5]:
        q.scene_lines(p[0], p[1])
    times = np.empty(len(pts))
    for i, (px, py) in enumerate(pts):
        t0 = time.perf_counter_ns()
        q.scene_lines(px, py)
        times[i] = time.perf_counter_ns() - t0
    return float(np.median(times) / 1e3)
