"""Global planning on a navigation graph: A* between nodes, the graph's connected parts.

Edge costs are Euclidean lengths, plus any ``extra`` cost per edge (the navigator's
coastal cost on stretches where the camera sees no wall, :func:`blind_lengths`); the
heuristic is the straight-line distance to the goal (admissible, so A* returns a cheapest
path). Edges flagged ``has_stairs`` are excluded by default (a wheeled base cannot take
them), and so are the edges given as ``excluded`` (node id pairs, either direction: the
navigator's edges found blocked).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Collection, Mapping

import numba
import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import WallIndex
from autonomy.maps.navgraph import NavGraph
from autonomy.maps.ray_hits import _segment_hit


class NoPathError(InputError):
    """Start and goal are not connected in the (filtered) graph.

    An InputError: raised out of the robot stack only for a goal that the place the
    robot was started at has no path to (the user's map or mission is wrong). A pose
    belief cut off from the goal is the robot's to recover from: the navigator plans
    from a node that reaches the goal (:func:`parts`)."""


def edge_key(a: int, b: int) -> tuple[int, int]:
    """An undirected edge's key: its two node ids, the smaller first."""
    return (a, b) if a <= b else (b, a)


def adjacency(
    graph: NavGraph,
    exclude_stairs: bool = True,
    excluded: Collection[tuple[int, int]] = (),
    extra: Mapping[tuple[int, int], float] | None = None,
) -> list[list[tuple[int, float]]]:
    """Adjacency lists by node index: (neighbour index, edge cost): the edge's length plus
    ``extra`` (by :func:`edge_key`; none: 0). ``excluded``: edges (node id pairs, either
    direction) left out."""
    xy = graph.node_xy()
    adj: list[list[tuple[int, float]]] = [[] for _ in range(len(xy))]
    skip = {edge_key(int(a), int(b)) for a, b in excluded}
    for e in graph.edges:
        if exclude_stairs and e.has_stairs:
            continue
        if skip and edge_key(e.s0_id, e.s1_id) in skip:
            continue
        a, b = graph.index_of(e.s0_id), graph.index_of(e.s1_id)
        d = float(math.hypot(*(xy[a] - xy[b])))
        if extra:
            d += extra.get(edge_key(e.s0_id, e.s1_id), 0.0)
        adj[a].append((b, d))
        adj[b].append((a, d))
    return adj


def astar(
    graph: NavGraph,
    start_id: int,
    goal_id: int,
    *,
    exclude_stairs: bool = True,
    excluded: Collection[tuple[int, int]] = (),
    extra: Mapping[tuple[int, int], float] | None = None,
) -> list[int]:
    """Node ids of a cheapest path from start to goal (both included), not using the
    ``excluded`` edges (node id pairs, both directions), each edge costing its length
    plus ``extra`` (non-negative, by :func:`edge_key`; none: a shortest path)."""
    xy = graph.node_xy()
    s, g = graph.index_of(start_id), graph.index_of(goal_id)
    adj = adjacency(graph, exclude_stairs, excluded, extra)
    gx, gy = xy[g]
    cost = {s: 0.0}
    parent = {s: -1}
    heap = [(math.hypot(xy[s, 0] - gx, xy[s, 1] - gy), 0.0, s)]
    closed = set()
    while heap:
        _, c, u = heapq.heappop(heap)
        if u in closed:
            continue
        if u == g:
            path = []
            while u != -1:
                path.append(graph.nodes[u].id)
                u = parent[u]
            return path[::-1]
        closed.add(u)
        for v, d in adj[u]:
            nc = c + d
            if nc < cost.get(v, math.inf):
                cost[v] = nc
                parent[v] = u
                heapq.heappush(heap, (nc + math.hypot(xy[v, 0] - gx, xy[v, 1] - gy), nc, v))
    raise NoPathError(f"no path from node {start_id} to node {goal_id} in the navigation graph")


def parts(graph: NavGraph, exclude_stairs: bool = True) -> np.ndarray:
    """(N,) label by node index of the connected part of the graph each node lies in,
    with the edges :func:`astar` uses by default (no stairs when ``exclude_stairs``):
    two nodes have a path between them exactly when their labels are equal."""
    adj = adjacency(graph, exclude_stairs)
    label = np.full(len(adj), -1, dtype=np.int64)
    n = 0
    for s in range(len(adj)):
        if label[s] >= 0:
            continue
        label[s] = n
        todo = [s]
        while todo:
            for v, _ in adj[todo.pop()]:
                if label[v] < 0:
                    label[v] = n
                    todo.append(v)
        n += 1
    return label


def path_length(graph: NavGraph, path: list[int]) -> float:
    """Length of a node path in metres."""
    if len(path) < 2:
        return 0.0
    xy = np.array([graph.node_xy()[graph.index_of(i)] for i in path])
    return float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))


def path_points(graph: NavGraph, path: list[int]) -> np.ndarray:
    """(n, 2) coordinates of a node path."""
    xy = graph.node_xy()
    return np.array([xy[graph.index_of(i)] for i in path], dtype=np.float64).reshape(-1, 2)


def dijkstra(adj: list[list[tuple[int, float]]], sources: dict[int, float]) -> tuple[np.ndarray, np.ndarray]:
    """Shortest distances from a set of sources over adjacency lists (:func:`adjacency`).

    ``sources`` maps node index -> starting distance (0 for a plain source; a goal seen
    from several nodes starts each at its straight-line distance). Returns (distance per
    node, inf where unreachable; parent index per node, -1 at the sources).
    """
    n = len(adj)
    dist = np.full(n, np.inf)
    parent = np.full(n, -1, dtype=np.int64)
    heap = [(float(d), int(i)) for i, d in sources.items()]
    for d, i in heap:
        dist[i] = d
    heapq.heapify(heap)
    while heap:
        d, u = heapq.heappop(heap)
        if d > dist[u]:
            continue
        for v, w in adj[u]:
            nd = d + w
            if nd < dist[v]:
                dist[v] = nd
                parent[v] = u
                heapq.heappush(heap, (nd, v))
    return dist, parent


@numba.njit(cache=True)
def _blind_kernel(
    pts: np.ndarray, heading: np.ndarray, walls: np.ndarray, offsets: np.ndarray, idx: np.ndarray,
    x0: float, y0: float, size: float, nx: int, ny: int, range_m: float, half_fov: float, n_rays: int, out: np.ndarray,
) -> None:  # pragma: no cover - numba
    """out[k]: 1 when none of ``n_rays`` rays across +-half_fov about heading[k] from
    pts[k] meets a wall within ``range_m`` (walls bucketed as :class:`WallIndex`)."""
    for k in range(pts.shape[0]):
        px, py = pts[k, 0], pts[k, 1]
        i0 = max(0, int((px - range_m - x0) / size))
        i1 = min(nx - 1, int((px + range_m - x0) / size))
        j0 = max(0, int((py - range_m - y0) / size))
        j1 = min(ny - 1, int((py + range_m - y0) / size))
        seen = False
        for r in range(n_rays):
            a = heading[k] + (-half_fov + 2.0 * half_fov * r / (n_rays - 1) if n_rays > 1 else 0.0)
            dx, dy = math.cos(a), math.sin(a)
            for j in range(j0, j1 + 1):
                for i in range(i0, i1 + 1):
                    b = j * nx + i
                    for t in range(offsets[b], offsets[b + 1]):
                        if _segment_hit(walls, idx[t], px, py, dx, dy, range_m) < range_m:
                            seen = True
                            break
                    if seen:
                        break
                if seen:
                    break
            if seen:
                break
        out[k] = 0.0 if seen else 1.0


def blind_lengths(
    graph: NavGraph, walls: np.ndarray, range_m: float, half_fov_rad: float, step_m: float = 0.25, rays: int = 9
) -> dict[tuple[int, int], float]:
    """Metres of each edge (by :func:`edge_key`; only edges with some) where a camera of
    that range and half field of view, facing along the edge, sees no wall: ``rays``
    rays across the view from the midpoints of pieces at most ``step_m`` long, driving
    either way (the mean of the two). There the localization, which matches walls only,
    dead-reckons: the blind stretches of coastal navigation (Roy, Burgard, Fox and
    Thrun, ICRA 1999). A wall beside the path is out of a 57 degree view beyond 1.9 m
    to the side at 4 m: a corridor 4 m wide is blind down its middle."""
    xy = graph.node_xy()
    keys = [edge_key(e.s0_id, e.s1_id) for e in graph.edges]
    segs = np.array([[*xy[graph.index_of(e.s0_id)], *xy[graph.index_of(e.s1_id)]] for e in graph.edges], dtype=np.float64)
    blind = BlindSegments(walls, range_m, half_fov_rad, step_m, rays).lengths(segs.reshape(-1, 4))
    return {k: float(b) for k, b in zip(keys, blind, strict=True) if b > 0}


class BlindSegments:
    """The blind metres (:func:`blind_lengths`) of any straight segments among the same
    walls, the walls indexed once."""

    def __init__(self, walls: np.ndarray, range_m: float, half_fov_rad: float, step_m: float = 0.25, rays: int = 9) -> None:
        if not (range_m > 0 and math.isfinite(range_m)):
            raise InputError(f"blind_lengths: range_m: expected a positive number, got {range_m!r}")
        if not (0 <= half_fov_rad < math.pi):
            raise InputError(f"blind_lengths: half_fov_rad: expected an angle in [0, pi), got {half_fov_rad!r}")
        w = np.ascontiguousarray(np.asarray(walls, dtype=np.float64).reshape(-1, 4))
        self.range_m, self.half_fov_rad, self.step_m, self.rays = float(range_m), float(half_fov_rad), float(step_m), int(rays)
        self.index = WallIndex(w, bucket_m=max(1.0, range_m)) if len(w) else None

    def lengths(self, segments: np.ndarray) -> np.ndarray:
        """(M,) blind metres of each segment (M, 4), the mean of driving it either way."""
        segs = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
        if not len(segs):
            return np.zeros(0)
        a, b = segs[:, :2], segs[:, 2:]
        length = np.hypot(*(b - a).T)
        n = np.maximum(1, np.ceil(length / self.step_m)).astype(np.int64)
        k = np.repeat(np.arange(len(segs)), n)
        f = (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n) + 0.5) / n[k]
        mid = a[k] + f[:, None] * (b - a)[k]
        h = np.arctan2((b - a)[:, 1], (b - a)[:, 0])[k]
        p = np.ascontiguousarray(np.vstack([mid, mid]))
        blind = np.ones(len(p))
        if self.index is not None:
            ix = self.index
            _blind_kernel(
                p, np.concatenate([h, h + math.pi]), ix.walls, ix.offsets, ix.idx, ix.x0, ix.y0, ix.bucket_m, ix.nx, ix.ny,
                self.range_m, self.half_fov_rad, self.rays, blind,
            )
        per = np.bincount(np.concatenate([k, k]), weights=blind, minlength=len(segs))
        return 0.5 * per * length / n
