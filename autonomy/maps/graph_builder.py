"""Navigation graphs made from the walls alone (UT AMRL ``navigation.json`` format).

1. :func:`~autonomy.maps.freespace.build_free_space` finds the inside regions where the robot fits.
2. The cells at least ``robot radius + margin`` from every wall are thinned to a
   one-cell skeleton (Zhang and Suen, "A fast parallel algorithm for thinning digital
   patterns", CACM 1984), which runs along corridor centre lines, through doorways into
   rooms and between pillars, and keeps the free space's topology (one piece per region).
3. The skeleton is traced into branches between junctions and ends; dead-end spurs that
   end within the junction's clearance plus ``spur_m`` (towards room corners, wall
   irregularities) are pruned.
4. Each branch becomes straight edges of at most ``max_edge_m`` that stay within
   ``tolerance_m`` of it and keep ``robot radius + margin`` from every wall, checked
   exactly against the segments (:class:`~autonomy.common.geometry.WallIndex`).
5. Free space farther than ``cover_radius_m`` from every edge (wide halls, open sites)
   gets a square lattice of nodes ``cover_spacing_m`` apart, turned to the walls' main
   direction, joined to its lattice neighbours and to the graph by clear straight edges;
   what the lattice misses (room corners) gets single nodes, farthest first.
6. The graph is thinned: nodes joined by an edge shorter than ``merge_m`` become one, and
   a node between two others is dropped when the straight edge between them stays clear,
   within ``tolerance_m`` of it and no longer than ``max_edge_m`` (a door edge is kept
   apart from the edges around it, so its speed limit stays on the doorway).

Every step keeps the clearance of every edge exact; the thinning trades at most
``tolerance_m`` of coverage at the graph's fringe for a few nodes per room.

Edges narrower than ``door_clearance_m`` are marked ``has_door`` with the door speed;
``max_clearance`` is each edge's exact clearance.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numba
import numpy as np

from autonomy.common.cache import cache_paths
from autonomy.common.constants import SAFETY_MARGIN_M
from autonomy.common.errors import require_positive
from autonomy.common.geometry import WallIndex
from autonomy.maps.freespace import (
    FreeSpace,
    FreeSpaceConfig,
    build_free_space,
    grid_distance,
    rasterise,
)
from autonomy.maps.vectormap import (
    DEFAULT_MAX_SPEED,
    NavEdge,
    NavGraph,
    NavNode,
    VectorMap,
    format_navgraph_json,
    parse_navgraph_json,
)

__all__ = ["GraphBuildConfig", "GraphBuild", "CachedGraph", "build_navgraph", "cached_navgraph", "load_or_build_navgraph", "graph_components"]


@dataclass(frozen=True)
class GraphBuildConfig:
    """Settings of the automatic navigation graph (metres, m/s)."""

    free_space: FreeSpaceConfig = field(default_factory=FreeSpaceConfig)
    """Grid, robot radius and inside/outside settings."""
    margin_m: float = SAFETY_MARGIN_M
    """Every edge keeps the robot radius plus this from every wall: the obstacle
    avoidance's own margin, so that it lets the robot through every edge (a passage
    narrower than that holds the robot at its mouth until its leg times out)."""
    max_edge_m: float = 6.0
    """Longest edge (the hand-made graphs' median edges are 3 to 6 m; a relocalizing robot
    looks for nodes 6 to 12 m away)."""
    tolerance_m: float = 0.25
    """An edge stays within this of the skeleton branch it replaces."""
    spur_m: float = 0.75
    """A dead end reaching less than this beyond its junction's clearance is pruned."""
    cover_radius_m: float = 1.5
    """Free space farther than this from every edge gets extra nodes."""
    cover_spacing_m: float = 3.0
    """Lattice spacing of the extra nodes (twice ``cover_radius_m``: a square lattice's
    edges then pass within ``cover_radius_m`` of every point between them)."""
    merge_m: float = 0.75
    """Nodes joined by an edge shorter than this become one, where the edges stay clear."""
    fill_clearance_m: float = 0.75
    """Extra nodes go where the walls are at least this far, where there is such a place."""
    door_clearance_m: float = 0.6
    """Edges with less clearance than this pass a doorway: ``has_door`` and ``door_speed_mps``."""
    door_speed_mps: float = 0.5
    """Speed limit of door edges (as in the shipped hand-made graphs)."""

    def __post_init__(self) -> None:
        require_positive(self, "graph.", "margin_m", "max_edge_m", "tolerance_m", "spur_m", "cover_radius_m",
                         "cover_spacing_m", "merge_m", "fill_clearance_m", "door_clearance_m", "door_speed_mps")

    @property
    def clearance_m(self) -> float:
        """The clearance every edge keeps from every wall."""
        return self.free_space.robot_radius_m + self.margin_m

    def key(self) -> str:
        """A stable text of the settings (part of the cache key)."""
        return json.dumps(asdict(self), sort_keys=True)


@dataclass(frozen=True, eq=False)
class GraphBuild:
    """A generated graph with the free space it was made from."""

    graph: NavGraph
    """The navigation graph."""
    free_space: FreeSpace
    """Where the robot fits, by region."""
    node_region: np.ndarray
    """(N,) region of each node (node order)."""
    component: np.ndarray
    """(N,) connected component of each node, 0 the largest."""
    narrow_regions: tuple[int, ...]
    """Regions the robot fits in but no edge with the margin does (no nodes there)."""
    split_regions: tuple[int, ...]
    """Regions whose graph falls into several components (a passage the robot fits
    through only without the margin)."""

    @property
    def n_components(self) -> int:
        """Connected components of the graph."""
        return int(self.component.max()) + 1 if self.component.size else 0

    def main_node_ids(self) -> np.ndarray:
        """Ids of the nodes in the largest connected component."""
        return self.graph.node_ids()[self.component == 0]

    def summary(self) -> str:
        """One line: nodes, edges, components, regions."""
        fs = self.free_space
        return (
            f"{self.graph.n_nodes} nodes, {self.graph.n_edges} edges, {self.n_components} component(s); "
            f"{fs.n_regions} inside region(s), {fs.region_area_m2.sum():.0f} m2 free for the robot "
            f"(largest {fs.region_area_m2[0]:.0f} m2)"
        )


# --------------------------------------------------------------------------- kernels

#: Node coordinates are written to the millimetre; edges are checked with this much to spare.
_ROUNDING_M = 0.001


@numba.njit(cache=True)
def _zs_deletable(img: np.ndarray, y: int, x: int, sub: int) -> bool:  # pragma: no cover - numba
    p2 = img[y + 1, x]
    p3 = img[y + 1, x + 1]
    p4 = img[y, x + 1]
    p5 = img[y - 1, x + 1]
    p6 = img[y - 1, x]
    p7 = img[y - 1, x - 1]
    p8 = img[y, x - 1]
    p9 = img[y + 1, x - 1]
    b = p2 + p3 + p4 + p5 + p6 + p7 + p8 + p9
    if b < 2 or b > 6:
        return False
    a = ((p2 == 0) & (p3 == 1)) + ((p3 == 0) & (p4 == 1)) + ((p4 == 0) & (p5 == 1)) + ((p5 == 0) & (p6 == 1)) \
        + ((p6 == 0) & (p7 == 1)) + ((p7 == 0) & (p8 == 1)) + ((p8 == 0) & (p9 == 1)) + ((p9 == 0) & (p2 == 1))
    if a != 1:
        return False
    if sub == 0:
        return p2 * p4 * p6 == 0 and p4 * p6 * p8 == 0
    return p2 * p4 * p8 == 0 and p2 * p6 * p8 == 0


@numba.njit(cache=True)
def thin(mask: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Zhang-Suen thinning of a boolean image (border cells count as background); only
    contour cells are revisited, so the cost follows the contour, not the image."""
    ny, nx = mask.shape
    img = np.zeros((ny, nx), dtype=np.uint8)
    for y in range(1, ny - 1):
        for x in range(1, nx - 1):
            if mask[y, x]:
                img[y, x] = 1
    stamp = np.zeros(ny * nx, dtype=np.int32)
    cand = []
    for y in range(1, ny - 1):
        for x in range(1, nx - 1):
            if img[y, x] and (img[y + 1, x] == 0 or img[y - 1, x] == 0 or img[y, x + 1] == 0 or img[y, x - 1] == 0
                              or img[y + 1, x + 1] == 0 or img[y - 1, x - 1] == 0 or img[y + 1, x - 1] == 0 or img[y - 1, x + 1] == 0):
                cand.append(y * nx + x)
    tick = 0
    while True:
        changed = False
        for sub in range(2):
            dele = []
            for c in cand:
                y, x = c // nx, c % nx
                if img[y, x] and _zs_deletable(img, y, x, sub):
                    dele.append(c)
            for c in dele:
                img[c // nx, c % nx] = 0
            if len(dele):
                changed = True
            tick += 1
            nxt = []
            for c in cand:
                if img[c // nx, c % nx] and stamp[c] != tick:
                    stamp[c] = tick
                    nxt.append(c)
            for c in dele:
                y, x = c // nx, c % nx
                for dy in range(-1, 2):
                    for dx in range(-1, 2):
                        yy, xx = y + dy, x + dx
                        if 0 < yy < ny - 1 and 0 < xx < nx - 1 and img[yy, xx]:
                            q = yy * nx + xx
                            if stamp[q] != tick:
                                stamp[q] = tick
                                nxt.append(q)
            cand = nxt
        if not changed:
            break
    return img.astype(np.bool_)


@numba.njit(cache=True)
def _trace(skel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """Branches of a skeleton between key cells (ends, junctions; one cell per key-free
    loop). Returns (cluster of each cell, -1 if none), branch start / end cluster, branch
    cell offsets and the flat cell indices of every branch, ends included."""
    ny, nx = skel.shape
    nb = np.zeros((ny, nx), dtype=np.int8)
    for y in range(1, ny - 1):
        for x in range(1, nx - 1):
            if skel[y, x]:
                s = 0
                for dy in range(-1, 2):
                    for dx in range(-1, 2):
                        if (dy or dx) and skel[y + dy, x + dx]:
                            s += 1
                nb[y, x] = s
    key = np.zeros((ny, nx), dtype=np.bool_)
    for y in range(ny):
        for x in range(nx):
            key[y, x] = skel[y, x] and nb[y, x] != 2
    # 8-connected clusters of key cells
    clus = np.full((ny, nx), -1, dtype=np.int32)
    stack = np.empty(ny * nx, dtype=np.int64)
    n_clus = 0
    for y0 in range(ny):
        for x0 in range(nx):
            if key[y0, x0] and clus[y0, x0] < 0:
                top = 0
                stack[0] = y0 * nx + x0
                clus[y0, x0] = n_clus
                while top >= 0:
                    c = stack[top]
                    top -= 1
                    y, x = c // nx, c % nx
                    for dy in range(-1, 2):
                        for dx in range(-1, 2):
                            yy, xx = y + dy, x + dx
                            if 0 <= yy < ny and 0 <= xx < nx and key[yy, xx] and clus[yy, xx] < 0:
                                clus[yy, xx] = n_clus
                                top += 1
                                stack[top] = yy * nx + xx
                n_clus += 1
    visited = np.zeros((ny, nx), dtype=np.bool_)
    b0 = []
    b1 = []
    offs = [0]
    cells = []
    for phase in range(2):
        for y0 in range(1, ny - 1):
            for x0 in range(1, nx - 1):
                if phase == 1 and skel[y0, x0] and not key[y0, x0] and not visited[y0, x0]:
                    key[y0, x0] = True  # a loop with no key cell: cut it here
                    clus[y0, x0] = n_clus
                    n_clus += 1
                if not key[y0, x0]:
                    continue
                if phase == 1 and clus[y0, x0] != n_clus - 1:
                    continue
                for dy in range(-1, 2):
                    for dx in range(-1, 2):
                        y, x = y0 + dy, x0 + dx
                        if (dy == 0 and dx == 0) or not skel[y, x] or key[y, x] or visited[y, x]:
                            continue
                        path = [y0 * nx + x0, y * nx + x]
                        visited[y, x] = True
                        py, px = y0, x0
                        end = -1
                        while True:
                            ny_, nx_ = -1, -1
                            for ey in range(-1, 2):
                                for ex in range(-1, 2):
                                    yy, xx = y + ey, x + ex
                                    if (ey == 0 and ex == 0) or (yy == py and xx == px) or not skel[yy, xx]:
                                        continue
                                    if key[yy, xx]:
                                        if ny_ < 0 or not key[ny_, nx_]:
                                            ny_, nx_ = yy, xx
                                    elif not visited[yy, xx] and ny_ < 0:
                                        ny_, nx_ = yy, xx
                            if ny_ < 0:
                                break
                            path.append(ny_ * nx + nx_)
                            if key[ny_, nx_]:
                                end = clus[ny_, nx_]
                                break
                            visited[ny_, nx_] = True
                            py, px, y, x = y, x, ny_, nx_
                        if end >= 0:
                            b0.append(clus[y0, x0])
                            b1.append(end)
                            for c in path:
                                cells.append(c)
                            offs.append(len(cells))
    n = len(b0)
    a0 = np.empty(n, dtype=np.int64)
    a1 = np.empty(n, dtype=np.int64)
    for i in range(n):
        a0[i] = b0[i]
        a1[i] = b1[i]
    o = np.empty(len(offs), dtype=np.int64)
    for i in range(len(offs)):
        o[i] = offs[i]
    cl = np.empty(len(cells), dtype=np.int64)
    for i in range(len(cells)):
        cl[i] = cells[i]
    return clus, a0, a1, o, cl, np.array([n_clus], dtype=np.int64)


def distance_to_segments(fs: FreeSpace, segments: np.ndarray) -> np.ndarray:
    """(ny, nx) grid distance in metres from each cell centre to the nearest of ``segments``
    (rasterised as the walls are; error below one cell)."""
    seg = np.ascontiguousarray(np.asarray(segments, dtype=np.float64).reshape(-1, 4))
    ny, nx = fs.shape
    if seg.shape[0] == 0:
        return np.full((ny, nx), np.inf, dtype=np.float32)
    return grid_distance(rasterise(seg, fs.origin[0], fs.origin[1], fs.cell_m, ny, nx), fs.cell_m)


# --------------------------------------------------------------------------- construction


class _Builder:
    """Nodes and edges under construction, with the exact clearance test."""

    def __init__(self, fs: FreeSpace, walls: WallIndex, cfg: GraphBuildConfig):
        self.fs, self.walls, self.cfg = fs, walls, cfg
        self.xy: list[tuple[float, float]] = []
        self.edges: dict[tuple[int, int], float] = {}

    def node(self, p: np.ndarray) -> int:
        self.xy.append((float(p[0]), float(p[1])))
        return len(self.xy) - 1

    def clear(self, a: np.ndarray, b: np.ndarray) -> float:
        return float(self.walls.clearances(np.array([[a[0], a[1], b[0], b[1]]]), 5.0)[0])

    def edge(self, i: int, j: int, clearance: float | None = None) -> None:
        if i == j:
            return
        k = (min(i, j), max(i, j))
        if k not in self.edges:
            if clearance is None:
                clearance = self.clear(np.asarray(self.xy[i]), np.asarray(self.xy[j]))
            self.edges[k] = clearance

    def chain(self, i: int, j: int, clearance: float) -> None:
        """Join i and j by a straight run of edges no longer than ``max_edge_m``."""
        a, b = np.asarray(self.xy[i]), np.asarray(self.xy[j])
        n = max(1, int(math.ceil(np.hypot(*(b - a)) / self.cfg.max_edge_m - 1e-9)))
        prev = i
        for k in range(1, n):
            m = self.node(a + (b - a) * k / n)
            self.edge(prev, m, clearance)
            prev = m
        self.edge(prev, j, clearance)

    def polyline(self, pts: np.ndarray, i: int, j: int) -> None:
        """Replace the skeleton branch ``pts`` (from node i to node j) by straight edges."""
        need, tol = self.cfg.clearance_m + _ROUNDING_M, self.cfg.tolerance_m
        ids = {0: i, len(pts) - 1: j}
        stack = [(0, len(pts) - 1)]
        while stack:
            s, e = stack.pop()
            a, b = pts[s], pts[e]
            if e - s <= 1:
                c = self.clear(a, b)
                if c >= need or np.hypot(*(b - a)) <= 1.5 * self.fs.cell_m:
                    self.chain(ids[s], ids[e], c)  # neighbouring cells: clear on the grid
                continue  # a representative a wall hides from its cluster's cell: no edge
            d = b - a
            L = float(np.hypot(*d))
            mid = pts[s + 1 : e]
            if L > 0:
                dev = np.abs((mid[:, 0] - a[0]) * d[1] - (mid[:, 1] - a[1]) * d[0]) / L
            else:
                dev = np.hypot(mid[:, 0] - a[0], mid[:, 1] - a[1])
            k = int(np.argmax(dev))
            if dev[k] <= tol:
                c = self.clear(a, b)
                if c >= need:
                    self.chain(ids[s], ids[e], c)
                    continue
            split = s + 1 + k if dev[k] > tol else (s + e) // 2
            ids[split] = self.node(pts[split])
            stack.append((s, split))
            stack.append((split, e))


def _branches(skel: np.ndarray, fs: FreeSpace, cfg: GraphBuildConfig) -> tuple[dict[int, np.ndarray], list[tuple[int, int, np.ndarray]]]:
    """Skeleton branches as (start cluster, end cluster, cell indices), spurs pruned and
    degree-2 clusters merged; and each kept cluster's representative cell."""
    clus, b0, b1, offs, cells, ncl = _trace(skel)
    n_clus = int(ncl[0])
    nx = fs.shape[1]
    flat_dist = fs.dist.ravel()
    # Representative cell of a cluster: its cell farthest from the walls.
    rows, cols = np.nonzero(clus >= 0)
    flat = rows * nx + cols
    cid = clus[rows, cols]
    order = np.lexsort((-flat_dist[flat], cid))
    first = np.ones(order.size, dtype=bool)
    first[1:] = cid[order][1:] != cid[order][:-1]
    rep = {int(c): int(f) for c, f in zip(cid[order][first], flat[order][first], strict=True)}
    branches: dict[int, tuple[int, int, np.ndarray]] = {}
    adj: dict[int, set[int]] = {c: set() for c in range(n_clus)}
    for k in range(b0.size):
        u, v = int(b0[k]), int(b1[k])
        if u == v and offs[k + 1] - offs[k] <= 3:
            continue
        branches[k] = (u, v, cells[offs[k] : offs[k + 1]])
        adj[u].add(k)
        adj[v].add(k)

    def xy(c: int) -> np.ndarray:
        f = rep[c]
        return fs.centres(np.array(f // nx), np.array(f % nx))

    def clearance(c: int) -> float:
        return float(flat_dist[rep[c]])

    # Prune spurs: dead ends that stay within their junction's clearance plus spur_m.
    changed = True
    while changed:
        changed = False
        for v in range(n_clus):
            deg = len(adj[v])
            if deg < 3:
                continue
            spurs = []
            for k in adj[v]:
                a, b, _ = branches[k]
                u = b if a == v else a
                if (u != v and len(adj[u]) == 1 and clearance(u) < clearance(v) - cfg.tolerance_m
                        and np.hypot(*(xy(u) - xy(v))) <= clearance(v) + cfg.spur_m):
                    spurs.append((np.hypot(*(xy(u) - xy(v))), k, u))
            if not spurs:
                continue
            if len(spurs) == deg:  # a star of spurs only: keep the longest
                spurs.sort()
                spurs = spurs[:-1]
            for _, k, u in spurs:
                adj[v].discard(k)
                adj[u].discard(k)
                del branches[k]
            changed = True
    # Merge branches through clusters of degree 2 (staircase cells, pruned junctions).
    for v in range(n_clus):
        if len(adj[v]) != 2:
            continue
        k1, k2 = tuple(adj[v])
        if branches[k1][0] == branches[k1][1] or branches[k2][0] == branches[k2][1]:
            continue
        a1, c1, p1 = branches[k1]
        a2, c2, p2 = branches[k2]
        if a1 == v:
            a1, c1, p1 = c1, a1, p1[::-1]
        if c2 == v:
            a2, c2, p2 = c2, a2, p2[::-1]
        # p1 ends at v, p2 starts at v
        merged = (a1, c2, np.concatenate([p1, p2[1:]]))
        del branches[k1], branches[k2]
        adj[v].clear()
        adj[a1].discard(k1)
        adj[c2].discard(k2)
        branches[k1] = merged
        adj[a1].add(k1)
        adj[c2].add(k1)
    used = {c for a, b, _ in branches.values() for c in (a, b)}
    reps = {c: xy(c) for c in used}
    out = []
    for a, b, p in branches.values():
        # the cluster's representative, then the branch's own cells (its end cells are in
        # the clusters): the step from the representative is then within the cluster
        pts = np.concatenate([reps[a][None], fs.centres(p // nx, p % nx), reps[b][None]])
        out.append((a, b, pts))
    return reps, out


@numba.njit(cache=True)
def _spread(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int], radius: int) -> np.ndarray:  # pragma: no cover - numba
    """Greedy farthest-first selection: take each candidate cell (given best first) unless
    an already taken one is within ``radius`` cells."""
    blocked = np.zeros(shape, dtype=np.bool_)
    take = np.zeros(rows.size, dtype=np.bool_)
    r2 = radius * radius
    for k in range(rows.size):
        y, x = rows[k], cols[k]
        if blocked[y, x]:
            continue
        take[k] = True
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                yy, xx = y + dy, x + dx
                if dy * dy + dx * dx <= r2 and 0 <= yy < shape[0] and 0 <= xx < shape[1]:
                    blocked[yy, xx] = True
    return take


def _graph_distance(b: _Builder, fs: FreeSpace) -> np.ndarray:
    """(ny, nx) grid distance to the nearest edge or node of the graph under construction."""
    segs = _segments(b)
    if len(b.xy):
        nodes = np.asarray(b.xy)
        segs = np.concatenate([segs, np.concatenate([nodes, nodes], axis=1)])
    return distance_to_segments(fs, segs)


def _cover(b: _Builder, fs: FreeSpace, graph_ok: np.ndarray, cfg: GraphBuildConfig, rounds: int = 3) -> None:
    """Add nodes where free space is farther than ``cover_radius_m`` from the graph: in each
    uncovered patch the farthest cells first, ``cover_spacing_m`` apart, each joined to
    the graph by clear straight edges."""
    target = fs.region >= 0
    for _ in range(rounds):
        far = _graph_distance(b, fs)
        uncovered = (far > cfg.cover_radius_m) & target
        if not uncovered.any():
            return
        # candidates: cells with the graph clearance in or next to an uncovered patch
        near = distance_to_cells(fs, uncovered) <= 0.5 * cfg.cover_spacing_m
        # prefer places away from the walls (a node in a room's corner would hug two walls,
        # and its edges would look like doorways): near a patch a roomy place can serve,
        # only roomy places are candidates
        roomy = near & graph_ok & (fs.clearance() >= max(cfg.clearance_m, cfg.fill_clearance_m))
        cand = roomy
        if roomy.any():
            served = distance_to_cells(fs, roomy) <= cfg.cover_radius_m
            rest = uncovered & ~served
            if rest.any():
                cand = roomy | (near & graph_ok & (distance_to_cells(fs, rest) <= 0.5 * cfg.cover_spacing_m))
        else:
            cand = near & graph_ok
        rows, cols = np.nonzero(cand)
        if rows.size == 0:
            return
        order = np.argsort(-far[rows, cols], kind="stable")
        rows, cols = rows[order], cols[order]
        take = _spread(rows, cols, fs.shape, max(1, int(round(cfg.cover_spacing_m / fs.cell_m))))
        added = [b.node(p) for p in fs.centres(rows[take], cols[take])]
        _connect(b, added, cfg)


def dominant_angle(segments: np.ndarray) -> float:
    """The walls' main direction modulo 90 degrees, in [0, pi/2): the length-weighted mode
    of the segment directions (1 degree bins), refined by the mean of those within 2 degrees."""
    d = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    d = d[:, 2:] - d[:, :2]
    w = np.hypot(d[:, 0], d[:, 1])
    if not (w > 0).any():
        return 0.0
    q = np.mod(4.0 * np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)  # directions mod 90 deg, times 4
    hist = np.bincount(np.minimum((q / (2 * np.pi) * 360).astype(np.int64), 359), weights=w, minlength=360)
    # smooth over neighbouring bins (circularly) before taking the mode
    sm = hist + np.roll(hist, 1) + np.roll(hist, -1)
    mode = (np.argmax(sm) + 0.5) / 360 * 2 * np.pi
    near = np.abs(np.angle(np.exp(1j * (q - mode)))) <= np.radians(8.0)
    z = np.sum(w[near] * np.exp(1j * q[near]))
    return float(np.mod(np.angle(z) if abs(z) > 0 else mode, 2 * np.pi) / 4.0)


def _lattice(b: _Builder, fs: FreeSpace, graph_ok: np.ndarray, cfg: GraphBuildConfig, theta: float) -> None:
    """A square lattice of nodes (``cover_spacing_m``, turned by ``theta``) where free space is
    farther than ``cover_radius_m`` from the graph, each joined to its lattice neighbours and,
    when one is within a lattice step, to the nearest old node it sees; a lattice piece that
    reaches no old node is joined by its shortest clear link (or left out when its region
    has other nodes, so that a region stays one component)."""
    far = _graph_distance(b, fs)
    uncovered = (far > cfg.cover_radius_m) & (fs.region >= 0)
    if not uncovered.any():
        return
    s = cfg.cover_spacing_m
    # lattice nodes only where the walls are at least fill_clearance_m away (a node by a
    # wall would make its edges look like doorways); _cover fills what is left
    ok = graph_ok & (distance_to_cells(fs, uncovered) <= 0.5 * s) & (fs.clearance() >= cfg.fill_clearance_m)
    rows, cols = np.nonzero(ok)
    if rows.size == 0:
        return
    c, sn = math.cos(theta), math.sin(theta)
    p = fs.centres(rows, cols)
    li = np.round((p[:, 0] * c + p[:, 1] * sn) / s).astype(np.int64)
    lj = np.round((-p[:, 0] * sn + p[:, 1] * c) / s).astype(np.int64)
    del p
    span = int(lj.max() - lj.min()) + 1
    flat = np.unique((li - li.min()) * span + (lj - lj.min()))
    ij = np.stack([flat // span + li.min(), flat % span + lj.min()], axis=1)
    u, v = ij[:, 0] * s, ij[:, 1] * s
    pts = np.stack([u * c - v * sn, u * sn + v * c], axis=1)
    r, k = fs.cell_of(pts)
    inside = ok[r, k] & (b.walls.clearances(np.concatenate([pts, pts], axis=1), 5.0) >= max(cfg.clearance_m, cfg.fill_clearance_m))
    ij, pts = ij[inside], pts[inside]
    if not len(pts):
        return
    n_old = len(b.xy)
    ids = {(int(i), int(j)): b.node(q) for (i, j), q in zip(ij, pts, strict=True)}
    need = cfg.clearance_m + _ROUNDING_M
    pairs = [(a, ids[(i + di, j + dj)]) for (i, j), a in ids.items() for di, dj in ((1, 0), (0, 1)) if (i + di, j + dj) in ids]
    if pairs:
        xy = np.asarray(b.xy)
        pa = np.array(pairs)
        cl = b.walls.clearances(np.concatenate([xy[pa[:, 0]], xy[pa[:, 1]]], axis=1), 5.0)
        for (a, q), cv in zip(pairs, cl, strict=True):
            if cv >= need:
                b.edge(a, q, float(cv))
    xy = np.asarray(b.xy)
    old = xy[:n_old]
    new = np.arange(n_old, len(xy))
    linked = np.zeros(len(xy), dtype=bool)
    if n_old:
        for i in new:
            d = np.hypot(old[:, 0] - xy[i, 0], old[:, 1] - xy[i, 1])
            j = int(np.argmin(d))
            if d[j] <= s and b.clear(xy[i], old[j]) >= need:
                b.chain(int(i), j, b.clear(xy[i], old[j]))
                linked[i] = True
    # lattice pieces: link each to the old graph by its shortest clear link
    ij_e = np.array([k for k in b.edges if k[0] >= n_old and k[1] >= n_old], dtype=np.int64).reshape(-1, 2) - n_old
    comp = graph_components(len(new), ij_e)
    region = fs.region_at(xy)
    old_regions = set(region[:n_old].tolist())
    for cpt in np.unique(comp):
        members = new[comp == cpt]
        if linked[members].any() or not n_old:
            continue
        d = np.hypot(xy[members, None, 0] - old[None, :, 0], xy[members, None, 1] - old[None, :, 1])
        order = np.argsort(d, axis=None)[:64]
        done = False
        for flat in order:
            mi, oj = np.unravel_index(flat, d.shape)
            if d[mi, oj] > 4.0 * cfg.cover_radius_m:
                break
            cv = b.clear(xy[members[mi]], old[oj])
            if cv >= need:
                b.chain(int(members[mi]), int(oj), cv)
                done = True
                break
        if not done and region[members[0]] in old_regions:
            for key in [k for k in b.edges if k[0] in set(members.tolist())]:
                del b.edges[key]


def _simplify(b: _Builder, cfg: GraphBuildConfig) -> None:
    """Merge nodes joined by a short edge and drop nodes between two others where a straight
    clear edge replaces them (see the module docstring); dropped nodes lose their edges."""
    need = cfg.clearance_m + _ROUNDING_M
    xy = np.asarray(b.xy)
    adj: dict[int, set[int]] = {i: set() for i in range(len(xy))}
    for i, j in b.edges:
        adj[i].add(j)
        adj[j].add(i)

    def key(i: int, j: int) -> tuple[int, int]:
        return (min(i, j), max(i, j))

    def is_door(i: int, j: int) -> bool:
        return b.edges[key(i, j)] < cfg.door_clearance_m

    def length(i: int, j: int) -> float:
        return float(math.hypot(*(xy[i] - xy[j])))

    # 1. short edges: the node with more neighbours stays
    short = sorted((length(i, j), i, j) for i, j in b.edges if length(i, j) < cfg.merge_m)
    for _, i, j in short:
        if key(i, j) not in b.edges:
            continue
        keep, drop = (i, j) if len(adj[i]) >= len(adj[j]) else (j, i)
        others = [w for w in adj[drop] if w != keep and w not in adj[keep]]
        if any(length(keep, w) > cfg.max_edge_m for w in others):
            continue
        cl = b.walls.clearances(np.array([[*xy[keep], *xy[w]] for w in others]).reshape(-1, 4), 5.0)
        if (cl < need).any():
            continue
        for w, cv in zip(others, cl, strict=True):
            b.edges[key(keep, w)] = float(cv)
            adj[keep].add(w)
            adj[w].add(keep)
        for w in list(adj[drop]):
            del b.edges[key(drop, w)]
            adj[w].discard(drop)
        adj[drop].clear()
    # 2. nodes between two others
    changed = True
    while changed:
        changed = False
        for m in range(len(xy)):
            if len(adj[m]) != 2:
                continue
            a, c = tuple(adj[m])
            if c in adj[a] or is_door(a, m) != is_door(m, c):
                continue
            ac = xy[c] - xy[a]
            L = float(math.hypot(*ac))
            if L > cfg.max_edge_m or L < 1e-9:
                continue
            t = float(np.dot(xy[m] - xy[a], ac)) / (L * L)
            if not 0.0 < t < 1.0 or abs(float(ac[0] * (xy[m][1] - xy[a][1]) - ac[1] * (xy[m][0] - xy[a][0]))) / L > cfg.tolerance_m:
                continue
            cv = b.clear(xy[a], xy[c])
            if cv < need:
                continue
            del b.edges[key(a, m)], b.edges[key(m, c)]
            adj[a].discard(m)
            adj[c].discard(m)
            adj[m].clear()
            b.edges[key(a, c)] = cv
            adj[a].add(c)
            adj[c].add(a)
            changed = True


def distance_to_cells(fs: FreeSpace, cells: np.ndarray) -> np.ndarray:
    """(ny, nx) grid distance in metres to the nearest True cell of ``cells``."""
    return grid_distance(cells, fs.cell_m)


def _connect(b: _Builder, added: list[int], cfg: GraphBuildConfig) -> None:
    """Join each new node to the nearest node it sees clearly and to the new nodes around
    it (a mesh across wide halls); a new node that can join nothing stays alone and is
    dropped at the end."""
    need = cfg.clearance_m + _ROUNDING_M
    xy = np.asarray(b.xy)
    reach = 4.0 * cfg.cover_radius_m
    is_new = np.zeros(len(xy), dtype=bool)
    is_new[added] = True
    for i in added:
        d = np.hypot(xy[:, 0] - xy[i, 0], xy[:, 1] - xy[i, 1])
        cand = np.flatnonzero((d <= reach) & (d > 1e-6))
        cand = cand[np.argsort(d[cand])]
        joined_old = False
        for j in cand:
            if is_new[j]:
                if d[j] > 1.25 * cfg.cover_spacing_m:
                    continue
            elif joined_old:
                continue
            c = b.clear(xy[i], xy[j])
            if c >= need:
                b.chain(i, int(j), c)
                joined_old = joined_old or not is_new[j]


def _segments(b: _Builder) -> np.ndarray:
    if not b.edges:
        return np.zeros((0, 4))
    xy = np.asarray(b.xy)
    ij = np.array(list(b.edges.keys()))
    return np.concatenate([xy[ij[:, 0]], xy[ij[:, 1]]], axis=1)


def graph_components(n_nodes: int, edges: np.ndarray) -> np.ndarray:
    """(N,) component of each node (edges as (E, 2) node indices), 0 the largest."""
    parent = np.arange(n_nodes)

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in edges:
        ra, rb = find(int(a)), find(int(b))
        if ra != rb:
            parent[ra] = rb
    roots = np.array([find(i) for i in range(n_nodes)], dtype=np.int64)
    uniq, inv, counts = np.unique(roots, return_inverse=True, return_counts=True)
    rank = np.empty(uniq.size, dtype=np.int64)
    rank[np.argsort(-counts, kind="stable")] = np.arange(uniq.size)
    return rank[inv]


def build_navgraph(vm: VectorMap, cfg: GraphBuildConfig = GraphBuildConfig()) -> GraphBuild:  # noqa: B008
    """The navigation graph of ``vm``'s free space (see the module docstring)."""
    fs = build_free_space(vm, cfg.free_space)
    need = cfg.clearance_m
    graph_ok = (fs.clearance() >= need) & (fs.region >= 0)
    skel = thin(graph_ok)
    walls = WallIndex(vm.segments)
    b = _Builder(fs, walls, cfg)
    reps, branches = _branches(skel, fs, cfg)
    ids = {c: b.node(p) for c, p in reps.items()}
    for a, c, pts in branches:
        b.polyline(pts, ids[a], ids[c])
    # Regions whose skeleton vanished (a blob a few cells across): one node at the widest cell.
    have = set(fs.region_at(np.asarray(b.xy)).tolist()) if b.xy else set()
    for r in range(fs.n_regions):
        if r in have:
            continue
        sel = graph_ok & (fs.region == r)
        if sel.any():
            k = int(np.argmax(np.where(sel, fs.dist, -1.0)))
            b.node(fs.centres(np.array(k // fs.shape[1]), np.array(k % fs.shape[1])))
    _lattice(b, fs, graph_ok, cfg, dominant_angle(vm.segments))
    _cover(b, fs, graph_ok, cfg, rounds=2)
    _simplify(b, cfg)
    return _finish(b, fs, cfg)


def _finish(b: _Builder, fs: FreeSpace, cfg: GraphBuildConfig) -> GraphBuild:
    xy = np.round(np.asarray(b.xy, dtype=np.float64).reshape(-1, 2), 3)
    ij = np.array(list(b.edges.keys()), dtype=np.int64).reshape(-1, 2)
    clear = np.array(list(b.edges.values()), dtype=np.float64)
    # Nodes that no edge uses are kept only when their region has no other node.
    deg = np.bincount(ij.ravel(), minlength=len(xy))
    region = fs.region_at(xy)
    keep = deg > 0
    for r in np.unique(region[~keep]):
        if r >= 0 and not np.any(keep & (region == r)):
            keep[np.flatnonzero(~keep & (region == r))[0]] = True
    new_id = np.cumsum(keep) - 1
    xy, region = xy[keep], region[keep]
    ij = new_id[ij]
    # each edge's own exact clearance (a piece of a chained run may clear more than the run)
    clear = b.walls.clearances(np.concatenate([xy[ij[:, 0]], xy[ij[:, 1]]], axis=1), 5.0)
    comp = graph_components(len(xy), ij)
    nodes = tuple(NavNode(int(i), float(x), float(y)) for i, (x, y) in enumerate(xy))
    edges = []
    for (i, j), c in zip(ij, clear, strict=True):
        door = c < cfg.door_clearance_m
        edges.append(NavEdge(int(i), int(j), has_door=bool(door), max_speed=cfg.door_speed_mps if door else DEFAULT_MAX_SPEED,
                             max_clearance=round(float(c), 3)))
    graph = NavGraph(nodes, tuple(edges))
    narrow = tuple(r for r in range(fs.n_regions) if not np.any(region == r))
    split = tuple(int(r) for r in range(fs.n_regions) if np.unique(comp[region == r]).size > 1)
    return GraphBuild(graph, fs, region.astype(np.int64), comp, narrow, split)


# --------------------------------------------------------------------------- cache


#: Bumped when the construction changes, so that cached graphs of the old one are rebuilt.
GENERATOR_VERSION = 2


def graph_key(vm: VectorMap, cfg: GraphBuildConfig) -> str:
    """Hash of the walls, the settings and the generator version (the cache key)."""
    h = hashlib.sha256()
    h.update(f"v{GENERATOR_VERSION}".encode())
    h.update(np.ascontiguousarray(vm.segments, dtype=np.float64).tobytes())
    h.update(cfg.key().encode())
    return h.hexdigest()


@dataclass(frozen=True)
class CachedGraph:
    """A graph from :func:`cached_navgraph`, with where it is kept and whether it was made."""

    graph: NavGraph
    """The navigation graph."""
    path: Path | None
    """The cache file holding it (None when no place was writable)."""
    built: bool
    """Made now (True) or read from the cache (False)."""


def cached_navgraph(
    vm: VectorMap, map_path: str | os.PathLike[str] | None, cfg: GraphBuildConfig = GraphBuildConfig()  # noqa: B008
) -> CachedGraph:
    """The automatic graph of ``vm``, cached as ``<map file>.auto.navigation.json`` (or under
    ``~/.cache/depthnav``) with the key in a ``"depthnav"`` entry the format's readers
    ignore. A stale, foreign or corrupt cache file is rebuilt, never an error."""
    key = graph_key(vm, cfg)
    paths = cache_paths(map_path, key, ".auto.navigation.json")
    for p in paths:
        if not p.is_file():
            continue
        try:
            text = p.read_text(encoding="utf-8")
            if json.loads(text).get("depthnav", {}).get("key") != key:
                continue
            return CachedGraph(parse_navgraph_json(text, str(p)), p, False)
        except (OSError, ValueError, AttributeError):
            continue
    graph = build_navgraph(vm, cfg).graph
    text = with_key(format_navgraph_json(graph), key)
    for p in cache_paths(map_path, key, ".auto.navigation.json", for_writing=True):
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(text, encoding="utf-8")
            return CachedGraph(graph, p, True)
        except OSError:
            continue
    return CachedGraph(graph, None, True)


def load_or_build_navgraph(
    vm: VectorMap, map_path: str | os.PathLike[str] | None, cfg: GraphBuildConfig = GraphBuildConfig()  # noqa: B008
) -> NavGraph:
    """The graph of :func:`cached_navgraph`."""
    return cached_navgraph(vm, map_path, cfg).graph


def with_key(text: str, key: str) -> str:
    """A navigation.json text with the generator's cache key as a ``"depthnav"`` entry."""
    head = '{\n  "depthnav": ' + json.dumps({"generator": "autonomy.maps.graph_builder", "key": key}) + ","
    assert text.startswith("{\n")
    return head + text[1:]
