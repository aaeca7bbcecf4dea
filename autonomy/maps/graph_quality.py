"""How good a navigation graph is for its map, measured against the free-space grid.

- coverage: the share of free cells (where the robot fits, inside the building) within
  ``cover_radius_m`` of an edge or node;
- clearance: the smallest exact distance from any edge to any wall;
- connectivity: the graph's connected components against the free space's regions;
- stretch: for random pairs of free points in the largest region, the shortest route
  over the graph (straight to a node the point sees, along the graph, straight to the
  end) divided by the shortest route over the free grid (16-connected Dijkstra over
  cells where the robot fits, within about 3 % of the true shortest path).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numba
import numpy as np

from autonomy.common.geometry import WallIndex
from autonomy.maps.freespace import FreeSpace
from autonomy.maps.graph_builder import distance_to_segments, graph_components
from autonomy.maps.navgraph import NavGraph
from autonomy.maps.planner import adjacency, dijkstra
from autonomy.maps.vectormap import VectorMap

__all__ = ["GraphQuality", "graph_quality", "grid_distances", "coverage"]

# 16-connected moves (dy, dx); a knight's move also needs the two cells it passes.
_MOVES = np.array(
    [(0, 1), (1, 0), (0, -1), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1),
     (1, 2), (2, 1), (-1, 2), (-2, 1), (1, -2), (2, -1), (-1, -2), (-2, -1)],
    dtype=np.int64,
)


@dataclass(frozen=True)
class GraphQuality:
    """Quality measures of a graph on its map."""

    coverage: float
    """Share of free cells within ``cover_radius_m`` of the graph."""
    cover_radius_m: float
    """The coverage radius."""
    min_clearance_m: float
    """Smallest exact edge-to-wall distance."""
    n_components: int
    """Connected components of the graph."""
    n_regions: int
    """Inside free-space regions of the map."""
    regions_without_nodes: int
    """Regions with no graph node."""
    stretch_median: float
    """Median graph-route / grid-route length ratio."""
    stretch_p90: float
    """90th percentile of that ratio."""
    n_pairs: int
    """Point pairs the stretch was measured on."""

    def as_dict(self) -> dict[str, float | int]:
        """The measures as a JSON-ready dict."""
        return {k: (round(v, 4) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


def coverage(graph: NavGraph, fs: FreeSpace, radius_m: float) -> float:
    """Share of the free cells (all regions) within ``radius_m`` of an edge or node."""
    xy = graph.node_xy()
    segs = np.concatenate([graph.edge_segments(), np.concatenate([xy, xy], axis=1)])
    d = distance_to_segments(fs, segs)
    free = fs.region >= 0
    return float(np.count_nonzero((d <= radius_m) & free) / max(1, np.count_nonzero(free)))


@numba.njit(cache=True)
def _grid_dijkstra(free: np.ndarray, sy: int, sx: int, cell: float, moves: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    ny, nx = free.shape
    dist = np.full((ny, nx), np.inf)
    dist[sy, sx] = 0.0
    heap = [(0.0, sy * nx + sx)]
    w = np.empty(moves.shape[0])
    for m in range(moves.shape[0]):
        w[m] = cell * math.hypot(moves[m, 0], moves[m, 1])
    while heap:
        d, c = heapq.heappop(heap)
        y, x = c // nx, c % nx
        if d > dist[y, x]:
            continue
        for m in range(moves.shape[0]):
            dy, dx = moves[m, 0], moves[m, 1]
            yy, xx = y + dy, x + dx
            if yy < 0 or xx < 0 or yy >= ny or xx >= nx or not free[yy, xx]:
                continue
            if abs(dy) + abs(dx) == 3:  # knight: the two cells it passes must be free
                if abs(dy) == 2:
                    if not (free[y + dy // 2, x] and free[y + dy // 2, xx]):
                        continue
                elif not (free[y, x + dx // 2] and free[yy, x + dx // 2]):
                    continue
            elif dy != 0 and dx != 0 and not (free[y, xx] and free[yy, x]):
                continue
            nd = d + w[m]
            if nd < dist[yy, xx]:
                dist[yy, xx] = nd
                heapq.heappush(heap, (nd, yy * nx + xx))
    return dist


def grid_distances(fs: FreeSpace, start_xy: np.ndarray, region: int = 0, factor: int = 2) -> tuple[np.ndarray, float, tuple[float, float]]:
    """Shortest free-space route lengths from ``start_xy`` to every cell of a coarser grid
    (``factor`` cells per side; a coarse cell is free when all its cells are in
    ``region``). Returns (distances, coarse cell size, coarse origin)."""
    ny, nx = fs.shape
    ny2, nx2 = ny // factor, nx // factor
    ok = (fs.region[: ny2 * factor, : nx2 * factor] == region).reshape(ny2, factor, nx2, factor).all(axis=(1, 3))
    cell = fs.cell_m * factor
    j = int((start_xy[0] - fs.origin[0]) / cell)
    i = int((start_xy[1] - fs.origin[1]) / cell)
    if not (0 <= i < ny2 and 0 <= j < nx2 and ok[i, j]):
        return np.full((ny2, nx2), np.inf), cell, fs.origin
    return _grid_dijkstra(ok, i, j, cell, _MOVES), cell, fs.origin


def _attach(p: np.ndarray, xy: np.ndarray, cand: np.ndarray, walls: WallIndex, need: float, k: int = 5) -> dict[int, float]:
    """Up to ``k`` of the nearest nodes (among ``cand``) that ``p`` reaches in a straight
    line keeping ``need`` from the walls, with their distances."""
    d = np.hypot(xy[cand, 0] - p[0], xy[cand, 1] - p[1])
    out: dict[int, float] = {}
    for n in cand[np.argsort(d)][: 8 * k]:
        seg = np.array([[p[0], p[1], xy[n, 0], xy[n, 1]]])
        if walls.clearances(seg, need + 0.01)[0] >= need:
            out[int(n)] = float(math.hypot(*(xy[n] - p)))
            if len(out) >= k:
                break
    return out


def graph_quality(
    graph: NavGraph,
    vm: VectorMap,
    fs: FreeSpace,
    rng: np.random.Generator,
    *,
    cover_radius_m: float = 1.5,
    n_sources: int = 6,
    n_targets: int = 12,
    min_pair_m: float = 5.0,
) -> GraphQuality:
    """Coverage, clearance, connectivity and stretch of ``graph`` on ``vm`` (see the module docstring)."""
    walls = WallIndex(vm.segments)
    clear = walls.clearances(graph.edge_segments(), 5.0)
    comp = graph_components(graph.n_nodes, graph.edge_indices())
    xy = graph.node_xy()
    node_region = fs.region_at(xy)
    adj = adjacency(graph)
    need = fs.config.robot_radius_m
    main = np.flatnonzero(node_region == 0)
    ratios: list[float] = []
    if main.size:
        pts = fs.sample(rng, n_sources + n_targets * n_sources, need + 0.1, region=0)
        for s in range(n_sources):
            a = pts[s]
            gd, cell, origin = grid_distances(fs, a)
            src = _attach(a, xy, main, walls, need)
            if not src:
                continue
            gdist, _ = dijkstra(adj, src)
            for b in pts[n_sources + s * n_targets : n_sources + (s + 1) * n_targets]:
                i, j = int((b[1] - origin[1]) / cell), int((b[0] - origin[0]) / cell)
                ref = gd[i, j] if 0 <= i < gd.shape[0] and 0 <= j < gd.shape[1] else np.inf
                if not np.isfinite(ref) or ref < min_pair_m:
                    continue
                dst = _attach(b, xy, main, walls, need)
                route = min((gdist[n] + d for n, d in dst.items()), default=np.inf)
                ratios.append(route / ref)
    r = np.asarray(ratios) if ratios else np.array([np.inf])
    return GraphQuality(
        coverage=coverage(graph, fs, cover_radius_m),
        cover_radius_m=cover_radius_m,
        min_clearance_m=float(clear.min()) if clear.size else math.inf,
        n_components=int(comp.max()) + 1 if comp.size else 0,
        n_regions=fs.n_regions,
        regions_without_nodes=int(sum(1 for reg in range(fs.n_regions) if not np.any(node_region == reg))),
        stretch_median=float(np.median(r)),
        # Pairs the graph cannot join count as infinite stretch: then the percentile picks
        # an element rather than interpolating between two (inf - inf would be NaN).
        stretch_p90=float(np.percentile(r, 90, method="linear" if np.isfinite(r).all() else "higher")),
        n_pairs=len(ratios),
    )
