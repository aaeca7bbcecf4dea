"""A* on navigation graphs against brute-force shortest paths, and blind lengths against brute-force ray casting."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
from autonomy.maps.planner import NoPathError, astar, blind_lengths, edge_key, path_length
from autonomy.maps.raycast import rays_hit


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


def _random_graph(rng: np.random.Generator, n: int) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """n nodes in a 20 m square and 2n distinct edges among them (fewer when n is small)."""
    xy = rng.uniform(0, 20, size=(n, 2))
    pairs = list(itertools.combinations(range(n), 2))
    return xy, [pairs[i] for i in rng.choice(len(pairs), size=min(len(pairs), 2 * n), replace=False)]


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10**6), st.integers(3, 12))
def test_astar_is_a_shortest_path(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    xy, edges = _random_graph(rng, n)
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
    xy, edges = _random_graph(rng, n)
    extra = {edge_key(10 + a, 10 + b): float(rng.uniform(0, 30)) for a, b in edges if rng.uniform() < 0.5}
    g = _graph(xy, edges)
    dist = _floyd(xy, edges, extra=extra)
    for a, b in [(0, n - 1), (1, n // 2)]:
        if math.isinf(dist[a, b]):
            continue
        p = astar(g, 10 + a, 10 + b, extra=extra)
        assert p[0] == 10 + a and p[-1] == 10 + b
        assert _cost(g, p, extra) == pytest.approx(dist[a, b])


def _blind_reference(g: NavGraph, walls: np.ndarray, range_m: float, half_fov: float, step_m: float, rays: int) -> dict:
    """Brute force: every ray against every wall with :func:`autonomy.maps.raycast.rays_hit`."""
    out = {}
    xy = g.node_xy()
    for e in g.edges:
        a, b = xy[g.index_of(e.s0_id)], xy[g.index_of(e.s1_id)]
        length = float(np.hypot(*(b - a)))
        n = max(1, math.ceil(length / step_m))
        h = math.atan2(*(b - a)[::-1])
        blind = 0
        for k in range(n):
            p = a + (k + 0.5) / n * (b - a)
            for head in (h, h + math.pi):
                ang = head + np.linspace(-half_fov, half_fov, rays)
                _, t = rays_hit(walls, p[0], p[1], np.column_stack([np.cos(ang), np.sin(ang)]))
                blind += not (t <= range_m).any()
        if blind:
            out[edge_key(e.s0_id, e.s1_id)] = 0.5 * blind * length / n
    return out


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10**6))
def test_blind_lengths_match_brute_force_ray_casting(seed: int) -> None:
    rng = np.random.default_rng(seed)
    walls = np.hstack([rng.uniform(0, 20, (25, 2)), np.zeros((25, 2))])
    walls[:, 2:] = walls[:, :2] + rng.uniform(-4, 4, (25, 2))
    xy = rng.uniform(0, 20, (8, 2))
    edges = [(i, (i + 1) % 8) for i in range(8)] + [(0, 4), (2, 6)]
    g = _graph(xy, edges)
    got = blind_lengths(g, walls, 3.5, math.radians(28.5), step_m=0.5, rays=9)
    want = _blind_reference(g, walls, 3.5, math.radians(28.5), 0.5, 9)
    assert got.keys() == want.keys()
    for k in want:
        assert got[k] == pytest.approx(want[k])


def test_blind_lengths_of_a_hall() -> None:
    """A 20 x 12 m hall, a 57 degree view of 3.5 m: down its middle only the end walls
    are seen, from 3.5 m; 1.5 m from a side wall the wall is always in view."""
    walls = np.array([[0, 0, 20, 0], [20, 0, 20, 12], [20, 12, 0, 12], [0, 12, 0, 0]], float)
    g = _graph(np.array([[1, 6], [19, 6], [1, 1.5], [19, 1.5]], float), [(0, 1), (2, 3)])
    got = blind_lengths(g, walls, 3.5, math.radians(28.5), step_m=0.01)
    assert got[edge_key(10, 11)] == pytest.approx(18.0 - 2.5, abs=0.02)  # each way blind until 3.5 m from the end wall
    assert edge_key(12, 13) not in got


def test_blind_lengths_reject_a_bad_range() -> None:
    g = _graph(np.array([[0, 0], [1, 0]], float), [(0, 1)])
    with pytest.raises(InputError, match="range_m"):
        blind_lengths(g, np.zeros((0, 4)), 0.0, 0.5)
    with pytest.raises(InputError, match="half_fov_rad"):
        blind_lengths(g, np.zeros((0, 4)), 3.0, 4.0)


def test_stairs_are_excluded_unless_allowed() -> None:
    xy = np.array([[0, 0], [10, 0], [5, 5]], float)
    g = _graph(xy, [(0, 1), (0, 2), (2, 1)], stairs={0})
    assert astar(g, 10, 11) == [10, 12, 11]
    assert astar(g, 10, 11, exclude_stairs=False) == [10, 11]


def test_dijkstra_matches_brute_force_relaxation_from_several_sources() -> None:
    import numpy as np

    from autonomy.maps.planner import dijkstra

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
