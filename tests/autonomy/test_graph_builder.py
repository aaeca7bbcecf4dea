"""Automatic navigation graphs: thinning keeps topology, graphs of maps with a known
layout, the quality measures against independent references (brute-force distances,
straight-line routes in a box), the shipped and the 100 x 100 m generated buildings,
and the cache."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import autonomy.maps.graph_builder as gbmod
from autonomy.common.geometry import WallIndex, point_segment_distance, segment_distances
from autonomy.maps.freespace import build_free_space, label_components
from autonomy.maps.graph_builder import (
    GraphBuildConfig,
    build_navgraph,
    cached_navgraph,
    graph_components,
    load_or_build_navgraph,
    thin,
)
from autonomy.maps.graph_quality import coverage, graph_quality, grid_distances
from autonomy.maps.navgraph import load_navgraph, parse_navgraph_json
from autonomy.maps.planner import astar, path_length
from sim.simulator import blueprints
from tests.helpers import box_segments, segments_map

NEED = GraphBuildConfig().clearance_m


def _exact_clearances(graph, vm) -> np.ndarray:
    """Brute force: every edge against every wall."""
    e, w = graph.edge_segments(), vm.segments
    ei, wi = np.meshgrid(np.arange(len(e)), np.arange(len(w)), indexing="ij")
    return segment_distances(e[ei.ravel()], w[wi.ravel()]).reshape(len(e), len(w)).min(axis=1)


def _holes(img: np.ndarray) -> int:
    _, sizes = label_components(~img)
    return sizes.size - 1


# --------------------------------------------------------------------------- thinning


def test_thinning_keeps_components_and_holes_and_is_one_cell_wide():
    img = np.zeros((60, 80), dtype=bool)
    img[5:25, 5:70] = True
    img[12:18, 30:40] = False  # a hole (a pillar)
    img[35:55, 10:30] = True  # a second piece
    sk = thin(img)
    assert sk.sum() < 0.2 * img.sum()
    assert not (sk & ~img).any()
    # components (8-connected: dilate by one diagonal step to join diagonal neighbours)
    grow = sk.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            grow |= np.roll(np.roll(sk, dy, 0), dx, 1) & img
    assert label_components(grow)[1].size == 2
    assert _holes(grow) == _holes(img)
    # no 2 x 2 block of skeleton cells
    assert not (sk[:-1, :-1] & sk[1:, :-1] & sk[:-1, 1:] & sk[1:, 1:]).any()


# --------------------------------------------------------------------------- known layouts


def test_a_corridor_gets_a_centre_line_of_short_edges():
    vm = segments_map([(0, 0, 20, 0), (0, 2, 20, 2), (0, 0, 0, 2), (20, 0, 20, 2)])
    gb = build_navgraph(vm)
    xy = gb.graph.node_xy()
    assert np.abs(xy[:, 1] - 1.0).max() < 0.1
    assert xy[:, 0].min() < 2.0 and xy[:, 0].max() > 18.0
    assert gb.graph.edge_lengths().max() <= GraphBuildConfig().max_edge_m + 1e-9
    assert gb.n_components == 1
    assert not any(e.has_door for e in gb.graph.edges)


def test_a_room_behind_a_doorway_is_reached_through_it():
    # corridor 0..12 x 0..2; a 4 x 4 room above it with a 0.9 m door at x = 6
    rows = [(0, 0, 12, 0), (0, 0, 0, 2), (12, 0, 12, 2), (0, 2, 5.55, 2), (6.45, 2, 12, 2)]
    rows += [(4, 2, 4, 6), (8, 2, 8, 6), (4, 6, 8, 6)]
    vm = segments_map(rows)
    gb = build_navgraph(vm)
    g = gb.graph
    assert gb.n_components == 1
    clear = _exact_clearances(g, vm)
    assert clear.min() >= NEED
    doors = [k for k, e in enumerate(g.edges) if e.has_door]
    assert doors, "the edge through the doorway is a door edge"
    seg = g.edge_segments()[doors]
    assert (np.minimum(seg[:, 1], seg[:, 3]) < 2.0).all() and (np.maximum(seg[:, 1], seg[:, 3]) > 2.0).all()
    assert all(g.edges[k].max_speed == GraphBuildConfig().door_speed_mps for k in doors)
    np.testing.assert_allclose([e.max_clearance for e in g.edges], np.round(clear, 3), atol=1e-3)
    room = [n.id for n in g.nodes if n.y > 3.0]
    hall = [n.id for n in g.nodes if n.y < 1.5]
    assert room and hall
    path = astar(g, hall[0], room[0])
    assert path_length(g, path) < 20.0


def test_a_doorway_too_narrow_for_the_robot_leaves_the_room_apart():
    rows = [(0, 0, 12, 0), (0, 0, 0, 2), (12, 0, 12, 2), (0, 2, 5.7, 2), (6.3, 2, 12, 2)]
    rows += [(4, 2, 4, 6), (8, 2, 8, 6), (4, 6, 8, 6)]
    gb = build_navgraph(segments_map(rows))
    assert gb.free_space.n_regions == 2
    assert gb.n_components == 2
    assert set(gb.node_region.tolist()) == {0, 1}


def test_nothing_outside_the_building():
    gb = build_navgraph(segments_map(box_segments(0, 0, 12, 8)))
    xy = gb.graph.node_xy()
    assert (xy[:, 0] > 0).all() and (xy[:, 0] < 12).all() and (xy[:, 1] > 0).all() and (xy[:, 1] < 8).all()


def test_graph_components_by_union_find():
    comp = graph_components(6, np.array([[0, 1], [1, 2], [4, 5]]))
    assert comp.tolist() == [0, 0, 0, 2, 1, 1] or comp.tolist() == [0, 0, 0, 1, 2, 2]
    assert comp[0] == 0  # the largest is 0


# --------------------------------------------------------------------------- quality measures


def test_coverage_matches_brute_force_distances():
    bp = blueprints.load_blueprint(blueprints.ASSETS_DIR / "small_floor")
    fs = build_free_space(bp.vectormap)
    g = bp.navgraph
    rows, cols = np.nonzero(fs.region >= 0)
    pick = np.random.default_rng(3).choice(rows.size, 4000, replace=False)
    pts = fs.centres(rows[pick], cols[pick])
    segs = np.concatenate([g.edge_segments(), np.concatenate([g.node_xy(), g.node_xy()], axis=1)])
    ref = (point_segment_distance(pts, segs).min(axis=1) <= 1.5).mean()
    assert coverage(g, fs, 1.5) == pytest.approx(ref, abs=0.02)


def test_grid_routes_in_an_empty_box_are_straight_lines():
    fs = build_free_space(segments_map(box_segments(0, 0, 20, 12)))
    d, cell, origin = grid_distances(fs, np.array([2.0, 2.0]))
    for target in ([18.0, 10.0], [18.0, 2.0], [5.0, 10.0]):
        i, j = int((target[1] - origin[1]) / cell), int((target[0] - origin[0]) / cell)
        straight = np.hypot(target[0] - 2.0, target[1] - 2.0)
        assert straight * 0.98 <= d[i, j] <= straight * 1.04


def test_wall_index_clearances_match_brute_force():
    bp = blueprints.load_blueprint(blueprints.ASSETS_DIR / "corridor_loop")
    rng = np.random.default_rng(4)
    q = np.concatenate([rng.uniform(-2, 62, (300, 2)), rng.uniform(-2, 42, (300, 2))], axis=1)[:, [0, 2, 1, 3]]
    q[:, 2:] = q[:, :2] + rng.normal(0, 2, (300, 2))
    got = WallIndex(bp.vectormap.segments).clearances(q, 3.0)
    w = bp.vectormap.segments
    ref = np.array([segment_distances(np.repeat(s[None], len(w), 0), w).min() for s in q])
    np.testing.assert_allclose(got, np.minimum(ref, 3.0), atol=1e-12)


@pytest.mark.parametrize("name", ["small_floor", "corridor_loop"])
def test_shipped_buildings_graphs_meet_the_quality_bar(name):
    bp = blueprints.load_blueprint(blueprints.ASSETS_DIR / name)
    gb = build_navgraph(bp.vectormap)
    assert _exact_clearances(gb.graph, bp.vectormap).min() >= NEED
    q = graph_quality(gb.graph, bp.vectormap, gb.free_space, np.random.default_rng(5))
    assert q.coverage >= 0.95
    assert q.n_components == q.n_regions == 1
    assert q.n_pairs >= 30
    assert q.stretch_median <= 1.3


def test_large_generated_floor_graph_meets_the_quality_bar():
    bp = blueprints.generate_building(blueprints.BuildingConfig.large(), 0)
    assert bp.vectormap.n_segments > 10_000
    gb = build_navgraph(bp.vectormap)
    q = graph_quality(gb.graph, bp.vectormap, gb.free_space, np.random.default_rng(6))
    assert q.coverage >= 0.95
    assert q.min_clearance_m >= NEED
    assert q.n_components == q.n_regions  # one component per inside region
    assert q.regions_without_nodes == 0
    assert q.stretch_median <= 1.3
    # the main component spans the hand-made graph's floor: every hand node is near one of
    # its edges (the generated graph is sparse: few nodes, long edges)
    g = gb.graph
    main_edges = np.array([gb.component[g.index_of(e.s0_id)] == 0 for e in g.edges])
    hand = bp.navgraph.node_xy()
    d = point_segment_distance(hand, g.edge_segments()[main_edges]).min(axis=1)
    assert np.percentile(d, 99) < 1.5


# --------------------------------------------------------------------------- cache


def test_the_graph_is_cached_beside_the_map_and_rebuilt_when_stale(tmp_path, monkeypatch):
    vm = segments_map(box_segments(0, 0, 10, 4))
    path = tmp_path / "box.vectormap.txt"
    g1 = load_or_build_navgraph(vm, path)
    cache = tmp_path / "box.vectormap.txt.auto.navigation.json"
    assert cache.is_file()
    assert json.loads(cache.read_text())["depthnav"]["key"]
    assert load_navgraph(cache).n_nodes == g1.n_nodes  # a plain navigation.json to other readers

    def boom(*a, **k):
        raise AssertionError("rebuilt although cached")

    monkeypatch.setattr(gbmod, "build_navgraph", boom)
    assert load_or_build_navgraph(vm, path).n_edges == g1.n_edges
    monkeypatch.undo()
    vm2 = segments_map(box_segments(0, 0, 10, 5))  # other walls: the key differs, the file is rebuilt
    g2 = load_or_build_navgraph(vm2, path)
    assert parse_navgraph_json(cache.read_text()).n_nodes == g2.n_nodes
    cache.write_text("{ not json")
    assert load_or_build_navgraph(vm2, path).n_nodes == g2.n_nodes


# --------------------------------------------------------------------------- large and open maps


def test_an_open_lot_gets_a_regular_lattice_that_covers_it():
    # three walls that close nothing; 30 x 20 m between them
    vm = segments_map([(0, 0, 30, 0), (0, 20, 30, 20), (0, 0, 0, 3)])
    gb = build_navgraph(vm)
    assert gb.free_space.is_open
    g = gb.graph
    assert _exact_clearances(g, vm).min() >= NEED
    assert gb.n_components == 1
    assert coverage(g, gb.free_space, 1.5) >= 0.95
    # sparse: about one node per 3 x 3 m lattice square (a 2 m lattice would need 150)
    assert g.n_nodes <= 0.75 * (30 * 20) / 2**2


def test_dominant_angle_of_turned_walls():
    for deg in (0.0, 17.0, 44.0, 63.0):
        t = np.radians(deg)
        rows = np.array(box_segments(0, 0, 10, 6), float)
        c, s = np.cos(t), np.sin(t)
        rot = np.stack([rows[:, 0] * c - rows[:, 1] * s, rows[:, 0] * s + rows[:, 1] * c,
                        rows[:, 2] * c - rows[:, 3] * s, rows[:, 2] * s + rows[:, 3] * c], axis=1)
        got = np.degrees(gbmod.dominant_angle(rot))
        assert abs((got - deg + 45) % 90 - 45) < 0.5


@pytest.mark.slow
def test_a_campus_sized_open_map_builds_within_memory(tmp_path):
    """A 440 x 480 m open site (building blocks along streets): a coarser grid, under 4 GB
    in a fresh process, and a graph that keeps the clearance (its time is measured by
    ``make bench``, row ``map_graph_campus``)."""
    import resource
    import subprocess
    import sys

    rng = np.random.default_rng(9)
    rows = []
    for bx in range(0, 440, 55):
        for by in range(0, 480, 60):
            w, h = rng.uniform(20, 40), rng.uniform(20, 40)
            rows += box_segments(bx, by, bx + w, by + h, gap=(bx + 5, bx + 6.2))
    path = tmp_path / "campus.vectormap.txt"
    from autonomy.maps.vectormap import save_vectormap

    save_vectormap(segments_map(rows), path)
    out = tmp_path / "campus.navigation.json"
    subprocess.run([sys.executable, "-m", "sim.cli", "map", "graph", str(path), "--out", str(out)], check=True,
                   capture_output=True, text=True)
    rss_gb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1e6
    assert rss_gb < 4.0
    g = load_navgraph(out)
    vm = segments_map(rows)
    assert WallIndex(vm.segments).clearances(g.edge_segments(), 5.0).min() >= NEED
    assert g.n_nodes > 1000


def test_a_read_only_map_folder_is_left_untouched(tmp_path, monkeypatch):
    """A shared folder of maps without write bits (root could still write there) gets no
    cache file; the graph is cached under the user's cache folder instead."""
    maps = tmp_path / "maps"
    maps.mkdir()
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    path = maps / "box.vectormap.txt"
    vm = segments_map(box_segments(0, 0, 10, 4))
    maps.chmod(0o555)
    try:
        cached = cached_navgraph(vm, path)
        assert list(maps.iterdir()) == []
        assert cached.path is not None and cached.path.is_relative_to(tmp_path / "home")
        assert cached_navgraph(vm, path).built is False  # read back from there
    finally:
        maps.chmod(0o755)


def test_quality_of_a_graph_that_leaves_pairs_unjoined_is_inf_not_nan():
    """A two-node graph in one room of small_floor reaches few of the sampled points: the
    unjoined pairs count as infinite stretch, and the 90th percentile says so (no NaN,
    no numpy warning)."""
    import warnings

    from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode

    bp = blueprints.load_blueprint(blueprints.ASSETS_DIR / "small_floor")
    gb = build_navgraph(bp.vectormap)
    tiny = NavGraph(nodes=(NavNode(0, 2.0, 5.1), NavNode(1, 3.9, 5.1)), edges=(NavEdge(0, 1),))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        q = graph_quality(tiny, bp.vectormap, gb.free_space, np.random.default_rng(5))
    assert not math.isnan(q.stretch_p90) and not math.isnan(q.stretch_median)
    assert q.stretch_p90 == math.inf
