"""Any-angle plans (autonomy.navigation.shortcut): straight where the map leaves room, the
graph's way through doors, round pillars and what blocked an edge, and along the walls
where coastal navigation chose them."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
from autonomy.maps.planner import BlindSegments
from autonomy.navigation.config import NavigatorConfig
from autonomy.navigation.navigator import Navigator
from autonomy.navigation.shortcut import Shortcuts

ROOM = np.array([[0, 0, 14, 0], [14, 0, 14, 3], [14, 3, 0, 3], [0, 3, 0, 0]], float)
"""A 14 x 3 m room: its long walls are in the camera's view (1.67 m to the side at 3.5 m)."""


def zigzag(door_at: int | None = None) -> NavGraph:
    """Nodes 1 m apart along a 14 x 3 m room's middle, 0.4 m to either side in turn (the
    triangulated graph of a hall); the edge from ``door_at`` on has a door."""
    nodes = tuple(NavNode(id=i, x=1.0 + i, y=1.5 + (0.4 if i % 2 else -0.4)) for i in range(13))
    edges = tuple(NavEdge(s0_id=i, s1_id=i + 1, has_door=(i == door_at)) for i in range(12))
    return NavGraph(nodes=nodes, edges=edges)


def turning(path: np.ndarray) -> float:
    d = np.diff(path, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0])
    return float(np.degrees(np.abs((np.diff(h) + math.pi) % (2 * math.pi) - math.pi).sum()))


def test_a_zigzag_through_an_open_room_becomes_one_straight_line() -> None:
    start = np.array([1.0, 1.1, 0.0])
    nav = Navigator(zigzag(), walls=ROOM)
    nav.set_goal(12, start, 0.0)
    assert nav.plan_nodes == list(range(13))  # the graph's route is kept ...
    np.testing.assert_allclose(nav.path, [[1.0, 1.1], [13.0, 1.1]])  # ... and driven straight
    assert len(nav.plan.shortcuts) == 1
    graph_way = Navigator(zigzag(), NavigatorConfig(shortcut_clearance_m=0.0), walls=ROOM)
    graph_way.set_goal(12, start, 0.0)
    assert len(graph_way.path) == 13 and turning(graph_way.path) > 400.0 and not len(graph_way.plan.shortcuts)
    # Without the walls nothing says where there is room: the graph's way.
    no_map = Navigator(zigzag())
    no_map.set_goal(12, start, 0.0)
    assert len(no_map.path) == 13


def test_a_door_is_driven_as_the_graph_lays_it() -> None:
    nav = Navigator(zigzag(door_at=6), walls=ROOM)
    nav.set_goal(12, np.array([1.0, 1.1, 0.0]), 0.0)
    xy = zigzag().node_xy()
    # Straight up to the door edge's first node, the door edge itself, straight on.
    np.testing.assert_allclose(nav.path, [[1.0, 1.1], xy[6], xy[7], xy[12]])
    assert nav.plan.narrow_s.shape[0] == 1  # the door's narrow stretch is still on the plan


def test_a_pillar_keeps_the_plan_its_clearance_away() -> None:
    pillar = np.array([[6.8, 0.5, 7.2, 0.5], [7.2, 0.5, 7.2, 0.9], [7.2, 0.9, 6.8, 0.9], [6.8, 0.9, 6.8, 0.5]])
    walls = np.vstack([ROOM, pillar])
    cfg = NavigatorConfig()
    nav = Navigator(zigzag(), walls=walls)
    nav.set_goal(12, np.array([1.0, 1.1, 0.0]), 0.0)
    assert len(nav.path) > 2
    from autonomy.common.geometry import WallIndex

    clear = WallIndex(walls).clearances(np.hstack([nav.path[:-1], nav.path[1:]]), 5.0)
    graph_edges = {(tuple(a), tuple(b)) for a, b in zip(zigzag().node_xy()[:-1], zigzag().node_xy()[1:], strict=True)}
    for seg, c in zip(np.hstack([nav.path[:-1], nav.path[1:]]), clear, strict=True):
        if (tuple(seg[:2]), tuple(seg[2:])) not in graph_edges:
            assert c >= cfg.shortcut_clearance_m - 1e-9, (seg, c)
    assert turning(nav.path) < 0.5 * turning(zigzag().node_xy())


def test_a_coastal_route_along_the_wall_is_not_cut_across_the_hall() -> None:
    """The hall of the coastal test: the way along the wall is kept, not cut across the
    blind middle, while without the coastal cost the straight crossing is the plan."""
    walls = np.array([[0, 0, 24, 0], [24, 0, 24, 14], [24, 14, 0, 14], [0, 14, 0, 0]], float)
    pts = {1: (2.0, 7.0), 2: (22.0, 7.0), 3: (2.0, 1.5), 4: (22.0, 1.5)}
    graph = NavGraph(
        nodes=tuple(NavNode(id=i, x=x, y=y) for i, (x, y) in pts.items()),
        edges=tuple(NavEdge(s0_id=a, s1_id=b) for a, b in [(1, 2), (1, 3), (3, 4), (4, 2)]),
    )
    nav = Navigator(graph, walls=walls)
    nav.set_goal(2, np.array([2.0, 7.0, 0.0]), 0.0)
    assert nav.plan_nodes == [1, 3, 4, 2]
    np.testing.assert_allclose(nav.path, [[2.0, 7.0], [2.0, 1.5], [22.0, 1.5], [22.0, 7.0]])


def test_what_blocks_a_straight_stretch_marks_the_graph_edges_nearest_it_and_is_kept_off() -> None:
    """A box on the straight line: marked on the graph edges nearest it, and a
    straightened line keeps the avoidance radius from what blocked."""
    nav = Navigator(zigzag(), walls=ROOM)
    pose = np.array([2.0, 1.1, 0.0])
    nav.set_goal(12, pose, 0.0)
    box = np.array([[dx, dy] for dx in (1.0, 1.1, 1.2) for dy in (-0.1, 0.0, 0.1)])  # robot frame, 1 m ahead
    assert nav.route.mark_blocked(nav.plan, pose, box, 0.0, nav.surroundings)
    assert set(nav.route.blocked) == {(1, 2), (2, 3)}
    sc = Shortcuts(ROOM, 0.6, 0.5, None)
    pts = zigzag().node_xy()
    keep, _ = sc.straighten(pts, np.ones(len(pts) - 1, bool), box + pose[:2], 0.4)
    from autonomy.common.geometry import point_segment_distance

    kept = np.hstack([pts[keep][:-1], pts[keep][1:]])
    assert keep.tolist() != [0, len(pts) - 1]
    short = kept[np.diff(keep) > 1]
    assert point_segment_distance(box + pose[:2], short).min() >= 0.4


def brute_clearance(a: np.ndarray, b: np.ndarray, walls: np.ndarray, n: int = 400) -> float:
    """The least distance from points along a-b to the walls' points (dense sampling)."""
    t = np.linspace(0.0, 1.0, n)
    p = a + t[:, None] * (b - a)
    w = np.concatenate([walls[:, :2] + s * (walls[:, 2:] - walls[:, :2]) for s in np.linspace(0.0, 1.0, n)])
    return float(np.sqrt(((p[:, None, :] - w[None, :, :]) ** 2).sum(-1)).min())


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_straighten_takes_the_farthest_vertex_with_room_as_brute_force_finds_it(seed: int) -> None:
    """Random polylines among random short walls (no coastal comparison): each kept
    segment has the clearance, and no later vertex of the same plain run had it."""
    rng = np.random.default_rng(seed)
    walls = np.hstack([rng.uniform(0, 10, (6, 2)), np.zeros((6, 2))])
    walls[:, 2:] = walls[:, :2] + rng.uniform(-1.0, 1.0, (6, 2))
    pts = np.cumsum(rng.uniform(-0.5, 1.5, (9, 2)), axis=0)
    plain = rng.random(8) < 0.85
    sc = Shortcuts(walls, 0.4, 0.5, None)
    keep, short = sc.straighten(pts, plain, np.zeros((0, 2)), 0.0)
    assert keep[0] == 0 and keep[-1] == len(pts) - 1 and np.all(np.diff(keep) >= 1)
    tol = 0.02  # the brute force samples; the index is exact
    for i, j, sh in zip(keep[:-1], keep[1:], short, strict=True):
        assert sh == (j > i + 1)
        assert plain[i:j].all() or j == i + 1
        if j > i + 1:
            assert brute_clearance(pts[i], pts[j], walls) >= 0.4 - tol
        end = i
        while end < len(pts) - 1 and plain[end]:
            end += 1
        for later in range(j + 1, end + 1):
            assert brute_clearance(pts[i], pts[later], walls) < 0.4 + tol, (i, j, later)


def test_the_blind_slack_is_measured_as_blind_lengths_measures_graph_edges() -> None:
    walls = np.array([[0, 0, 24, 0], [24, 0, 24, 14], [24, 14, 0, 14], [0, 14, 0, 0]], float)
    b = BlindSegments(walls, 3.5, math.radians(28.5), step_m=0.01)
    got = b.lengths(np.array([[2.0, 7.0, 22.0, 7.0], [2.0, 1.5, 22.0, 1.5]]))
    # Across the middle: blind but for the last 1.5 m before each end wall (either way),
    # give or take the view's width; along the wall 1.5 m away: never blind.
    assert got[0] == pytest.approx(18.5, abs=0.3) and got[1] == pytest.approx(0.0, abs=1e-9)


def test_shortcut_config_is_checked() -> None:
    for name in ("shortcut_clearance_m", "shortcut_blind_slack_m"):
        with pytest.raises(InputError, match=f"navigator.{name}"):
            NavigatorConfig(**{name: -0.1})


def test_the_plan_previewed_is_the_plan_driven() -> None:
    """plan_points and plan_length (the relocalization's choice of a place to look from,
    the mission's leg budget) give the straightened plan that set_goal then makes."""
    nav = Navigator(zigzag(), walls=ROOM)
    pose = np.array([1.0, 1.1, 0.0])
    preview, length = nav.plan_points(12, pose), nav.plan_length(12, pose)
    nav.set_goal(12, pose, 0.0)
    np.testing.assert_array_equal(preview, nav.path)
    assert length == pytest.approx(nav.plan.length_m) and length == pytest.approx(12.0)


def test_an_obstacle_on_a_straight_stretch_far_from_every_graph_edge_marks_the_nearest() -> None:
    """Nodes 2 m to either side of a straight line in turn (no coastal comparison): a box
    on the line 0.9 m from the nearest edge blocks the plan, and the edge nearest it is
    marked (without the straightened stretch nothing near the graph's edges blocks)."""
    room = np.array([[0, 0, 14, 0], [14, 0, 14, 4], [14, 4, 0, 4], [0, 4, 0, 0]], float)
    graph = NavGraph(
        nodes=tuple(NavNode(id=i, x=1.0 + i, y=1.0 if i % 2 == 0 else 3.0) for i in range(13)),
        edges=tuple(NavEdge(s0_id=i, s1_id=i + 1) for i in range(12)),
    )
    cfg = NavigatorConfig(coastal_weight=0.0)
    nav = Navigator(graph, cfg, walls=room)
    pose = np.array([5.0, 1.0, 0.0])
    nav.set_goal(12, pose, 0.0)
    np.testing.assert_allclose(nav.path, [[5.0, 1.0], [13.0, 1.0]])
    box = np.array([[1.0, dy] for dy in (-0.05, 0.0, 0.05)])  # (6, 1) in the world, 1 m ahead
    assert nav.route.mark_blocked(nav.plan, pose, box, 0.0, nav.surroundings)
    assert set(nav.route.blocked) <= {(4, 5), (5, 6)} and len(nav.route.blocked) == 1
    graph_way = Navigator(graph, NavigatorConfig(coastal_weight=0.0, shortcut_clearance_m=0.0), walls=room)
    graph_way.set_goal(12, pose, 0.0)
    assert not graph_way.route.mark_blocked(graph_way.plan, pose, box, 0.0, graph_way.surroundings)
