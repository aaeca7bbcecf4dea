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

import numpy as np

from autonomy.errors import InputError
from autonomy.geometry import WallIndex
from autonomy.vectormap import NavGraph


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


def blind_lengths(graph: NavGraph, walls: np.ndarray, range_m: float, step_m: float = 0.25) -> dict[tuple[int, int], float]:
    """Metres of each edge (by :func:`edge_key`; only edges with some) farther than
    ``range_m`` from every wall, measured at the midpoints of pieces at most ``step_m``
    long: where a depth camera of that range sees no wall, the localization dead-reckons
    (the blind stretches of coastal navigation, Roy, Burgard, Fox and Thrun, ICRA 1999)."""
    if not (range_m > 0 and math.isfinite(range_m)):
        raise InputError(f"blind_lengths: range_m: expected a positive number, got {range_m!r}")
    w = np.asarray(walls, dtype=np.float64).reshape(-1, 4)
    xy = graph.node_xy()
    keys: list[tuple[int, int]] = []
    mids: list[np.ndarray] = []
    piece: list[float] = []
    for e in graph.edges:
        a, b = xy[graph.index_of(e.s0_id)], xy[graph.index_of(e.s1_id)]
        length = float(math.hypot(*(b - a)))
        n = max(1, math.ceil(length / step_m))
        t = (np.arange(n) + 0.5) / n
        keys.append(edge_key(e.s0_id, e.s1_id))
        mids.append(a + t[:, None] * (b - a))
        piece.append(length / n)
    if not keys:
        return {}
    counts = [len(m) for m in mids]
    pts = np.vstack(mids)
    if len(w):
        clear = WallIndex(w, bucket_m=max(1.0, range_m)).clearances(np.hstack([pts, pts]), range_m)
    else:
        clear = np.full(len(pts), range_m)
    blind = np.add.reduceat((clear >= range_m).astype(np.float64), np.cumsum([0] + counts[:-1]))
    return {k: float(c * p) for k, c, p in zip(keys, blind, piece, strict=True) if c > 0}
