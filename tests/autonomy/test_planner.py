"""A* on navigation graphs against brute-force shortest paths."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.planner import NoPathError, astar, blind_lengths, edge_key, path_length
from autonomy.errors import InputError
from autonomy.vectormap import NavEdge, NavGraph, NavNode


def _graph(xy: np.ndarray, edges: list[tuple[int, int]], stairs: set[int] = frozenset()) -> NavGraph:
    nodes = tuple(NavNode(id=int(10 + i), x=float(p[0]), y=float(p[1])) for i, p in enumerate(xy))
    es = tuple(NavEdge(s0_id=10 + a, s1_id=10 + b, has_stairs=(k in stairs)) for k, (a, b) in enumerate(edges))
    return NavGraph(nodes=nodes, edges=es)


def _floyd(xy: np.ndarray, edges, stairs=frozenset(), extra=None) -> np.ndarray:
    n = len(xy)
    d = np.full((n, n), math.inf)
    np.fill_diagonal(d, 0)
    for k, (a, b) in enumerate(edges):
        if k in stairs:
            continue
        L = float(np.hypot(*(xy[a] - xy[b]))) + (0.0 if extra is None else extra.get(edge_key(10 + a, 10 + b), 0.0))
        d[a, b] = d[b, a] = min(d[a, b], L)
    for k in range(n):
        d = np.minimum(d, d[:, k : k + 1] + d[k : k + 1, :])
    return d


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10**6), st.integers(3, 12))
def test_astar_is_a_shortest_path(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 20, size=(n, 2))
    pairs = list(itertools.combinations(range(n), 2))
    edges = [pairs[i] for i in rng.choice(len(pairs), size=min(len(pairs), 2 * n), replace=False)]
    stairs = {int(k) for k in rng.choice(len(edges), size=len(edges) // 5, replace=False)}
    g = _graph(xy, edges, stairs)
    dist = _floyd(xy, edges, stairs)
    for a, b in [(0, n - 1), (1, n // 2)]:
        if math.isinf(dist[a, b]):
            with pytest.raises(NoPathError):
                astar(g, 10 + a, 10 + b)
        else:
            p = astar(g, 10 + a, 10 + b)
            assert p[0] == 10 + a and p[-1] == 10 + b
            assert path_length(g, p) == pytest.approx(dist[a, b])


def _cost(g: NavGraph, path: list[int], extra: dict) -> float:
    return path_length(g, path) + sum(extra.get(edge_key(a, b), 0.0) for a, b in zip(path, path[1:], strict=False))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10**6), st.integers(3, 12))
def test_astar_with_extra_edge_costs_is_a_cheapest_path(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 20, size=(n, 2))
    pairs = list(itertools.combinations(range(n), 2))
    edges = [pairs[i] for i in rng.choice(len(pairs), size=min(len(pairs), 2 * n), replace=False)]
    extra = {edge_key(10 + a, 10 + b): float(rng.uniform(0, 30)) for a, b in edges if rng.uniform() < 0.5}
    g = _graph(xy, edges)
    dist = _floyd(xy, edges, extra=extra)
    for a, b in [(0, n - 1), (1, n // 2)]:
        if math.isinf(dist[a, b]):
            continue
        p = astar(g, 10 + a, 10 + b, extra=extra)
        assert p[0] == 10 + a and p[-1] == 10 + b
        assert _cost(g, p, extra) == pytest.approx(dist[a, b])


def test_blind_lengths_match_a_fine_brute_force_sampling() -> None:
    """A 20 x 12 m hall: each edge's metres farther than 3 m from every wall, against
    the distance to the walls sampled every millimetre."""
    walls = np.array([[0, 0, 20, 0], [20, 0, 20, 12], [20, 12, 0, 12], [0, 12, 0, 0]], float)
    xy = np.array([[1, 6], [19, 6], [10, 1], [10, 11], [2.5, 2.5]], float)
    edges = [(0, 1), (2, 3), (0, 4), (4, 2), (1, 3)]
    g = _graph(xy, edges)
    got = blind_lengths(g, walls, 3.0, step_m=0.01)
    for a, b in edges:
        t = (np.arange(100000) + 0.5) / 100000
        p = xy[a] + t[:, None] * (xy[b] - xy[a])
        clear = np.minimum.reduce([p[:, 0], 20 - p[:, 0], p[:, 1], 12 - p[:, 1]])
        want = float(np.hypot(*(xy[b] - xy[a]))) * float(np.mean(clear >= 3.0))
        assert got.get(edge_key(10 + a, 10 + b), 0.0) == pytest.approx(want, abs=0.02)
    assert got[edge_key(10, 11)] == pytest.approx(14.0, abs=0.02)  # x from 3 to 17 at y = 6
    assert edge_key(10, 14) not in got  # (1, 6) to (2.5, 2.5): never 3 m from the walls


def test_blind_lengths_reject_a_bad_range() -> None:
    g = _graph(np.array([[0, 0], [1, 0]], float), [(0, 1)])
    with pytest.raises(InputError, match="range_m"):
        blind_lengths(g, np.zeros((0, 4)), 0.0)


def test_stairs_are_excluded_unless_allowed() -> None:
    xy = np.array([[0, 0], [10, 0], [5, 5]], float)
    g = _graph(xy, [(0, 1), (0, 2), (2, 1)], stairs={0})
    assert astar(g, 10, 11) == [10, 12, 11]
    assert astar(g, 10, 11, exclude_stairs=False) == [10, 11]


def test_dijkstra_matches_brute_force_relaxation_from_several_sources() -> None:
    import numpy as np

    from autonomy.planner import dijkstra

    rng = np.random.default_rng(4)
    n = 30
    adj: list[list[tuple[int, float]]] = [[] for _ in range(n)]
    for _ in range(60):
        a, b = (int(v) for v in rng.integers(0, n, 2))
        if a != b:
            w = float(rng.uniform(0.1, 5.0))
            adj[a].append((b, w))
            adj[b].append((a, w))
    sources = {0: 0.0, 7: 1.5}
    dist, parent = dijkstra(adj, sources)
    # Bellman-Ford as the reference.
    ref = np.full(n, np.inf)
    for s, d in sources.items():
        ref[s] = min(ref[s], d)
    for _ in range(n):
        for u in range(n):
            for v, w in adj[u]:
                ref[v] = min(ref[v], ref[u] + w)
    np.testing.assert_allclose(dist, ref)
    for v in range(n):
        if np.isfinite(dist[v]) and parent[v] >= 0:
            assert any(x == v and np.isclose(dist[parent[v]] + w, dist[v]) for x, w in adj[parent[v]])
