"""The graph under construction and its thinning (steps 4 and 6 of
:mod:`autonomy.maps.graph_builder`).

Each skeleton branch becomes straight edges of at most ``max_edge_m`` that stay within
``tolerance_m`` of it and keep ``robot radius + margin`` from every wall, checked exactly
against the segments (:class:`~autonomy.common.geometry.WallIndex`). The graph is then
thinned: nodes joined by an edge shorter than ``merge_m`` become one, and a node between
two others is dropped when the straight edge between them stays clear, within
``tolerance_m`` of it and no longer than ``max_edge_m`` (a door edge is kept apart from
the edges around it, so its speed limit stays on the doorway).
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import WallIndex
from autonomy.maps.freespace import FreeSpace
from autonomy.maps.graph_config import GraphBuildConfig

__all__ = ["graph_components"]

#: Node coordinates are written to the millimetre; edges are checked with this much to spare.
_ROUNDING_M = 0.001


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
