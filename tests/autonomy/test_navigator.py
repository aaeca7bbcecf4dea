"""The navigator's decisions on a known plan: carrot, turning, blocking, recovery, arrival."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.common.geometry import point_segment_distance
from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
from autonomy.navigation.config import NavigatorConfig
from autonomy.navigation.navigator import Navigator
from autonomy.navigation.surroundings import in_camera_view, wall_points
from autonomy.perception.camera import DepthCamera


def line_graph() -> NavGraph:
    nodes = tuple(NavNode(id=i, x=float(2 * i), y=0.0) for i in range(6))
    edges = tuple(NavEdge(s0_id=i, s1_id=i + 1) for i in range(5))
    return NavGraph(nodes=nodes, edges=edges)


def test_drives_towards_the_carrot_at_cruise_speed() -> None:
    nav = Navigator(line_graph())
    nav.set_goal(5, np.array([0.0, 0.0, 0.0]))
    cmd = nav.command(np.array([0.0, 0.0, 0.0]), np.zeros((0, 2)), 0.0)
    assert cmd.state == "driving"
    np.testing.assert_allclose(cmd.velocity, [0.75, 0.0, 0.0], atol=1e-9)


def test_turns_to_look_before_driving_where_the_camera_does_not_look() -> None:
    """The carrot 40 degrees to the left (inside the turn-in-place threshold) but outside
    the camera's +-29 degrees: turn in place towards it first (look_first); without
    look_first, drive there slowly while turning to look; once the direction is in view,
    at cruise speed again."""
    nav = Navigator(line_graph())
    nav.set_goal(5, np.zeros(3))
    pose = np.array([0.0, 0.0, -math.radians(40.0)])
    cmd = nav.command(pose, np.zeros((0, 2)), 0.0)
    assert cmd.state == "turning" and abs(cmd.theta_star_rad) > math.radians(29.0)
    assert np.hypot(*cmd.velocity[:2]) == 0.0 and cmd.velocity[2] > 0
    nav = Navigator(line_graph(), NavigatorConfig(look_first=False))
    nav.set_goal(5, np.zeros(3))
    cmd = nav.command(pose, np.zeros((0, 2)), 0.0)
    assert cmd.state == "driving" and abs(cmd.theta_star_rad) > math.radians(29.0)
    assert np.hypot(*cmd.velocity[:2]) == pytest.approx(0.3) and cmd.velocity[2] > 0
    nav = Navigator(line_graph(), NavigatorConfig(look_first=False, unseen_speed_mps=0.0))
    nav.set_goal(5, np.zeros(3))
    assert np.hypot(*nav.command(pose, np.zeros((0, 2)), 0.0).velocity[:2]) == pytest.approx(0.75)
    nav = Navigator(line_graph())
    nav.set_goal(5, np.zeros(3))
    assert np.hypot(*nav.command(np.array([0.0, 0.0, -0.3]), np.zeros((0, 2)), 0.0).velocity[:2]) == pytest.approx(0.75)
    with pytest.raises(InputError, match="unseen_speed_mps"):
        NavigatorConfig(unseen_speed_mps=-1.0)


def test_turns_in_place_when_the_goal_is_behind() -> None:
    nav = Navigator(line_graph())
    nav.set_goal(0, np.array([6.0, 0.0, 0.0]))
    cmd = nav.command(np.array([6.0, 0.0, 0.0]), np.zeros((0, 2)), 0.0)
    assert cmd.state == "turning" and cmd.velocity[:2].tolist() == [0.0, 0.0] and abs(cmd.velocity[2]) > 1.0


def test_steers_around_an_obstacle_and_stops_for_a_wall() -> None:
    # The box's face alone (no shadow behind it), so that the carrot stays on the plan.
    nav = Navigator(line_graph(), NavigatorConfig(shadow_m=0.0))
    nav.set_goal(5, np.zeros(3))
    # A box 1.2 m ahead, straddling the path: steer off the straight line.
    # The way round lies just outside the camera's view: turn towards it first.
    box = np.array([[1.2, y] for y in np.linspace(-0.3, 0.3, 13)])
    cmd = nav.command(np.zeros(3), box, 0.0)
    assert cmd.state == "turning" and abs(cmd.theta_star_rad) > math.radians(29.0)
    nav = Navigator(line_graph(), NavigatorConfig(look_first=False, shadow_m=0.0))
    nav.set_goal(5, np.zeros(3))
    cmd = nav.command(np.zeros(3), box, 0.0)
    assert cmd.state == "driving" and abs(cmd.theta_star_rad) > 0.2
    nav = Navigator(line_graph())
    nav.set_goal(5, np.zeros(3))
    # A wall across the whole fan, 0.4 m ahead: blocked, no translation (current frame only).
    wall = np.array([[0.4, y] for y in np.linspace(-3, 3, 121)])
    nav = Navigator(line_graph(), NavigatorConfig(memory_s=0.0))
    nav.set_goal(5, np.zeros(3))
    cmd = nav.command(np.zeros(3), wall, 0.0)
    assert cmd.state == "blocked" and np.hypot(*cmd.velocity[:2]) == 0.0


def drive_in(nav: Navigator, x0: float, x1: float, t0: float = 0.0) -> float:
    """Feed the navigator poses along y = 0 from x0 to x1 (0.75 m/s, 30 Hz, nothing
    sensed): the trail a back-off may use. Returns the time after the last frame."""
    t = t0
    for x in np.arange(x0, x1, 0.025):
        nav.command(np.array([x, 0.0, 0.0]), np.zeros((0, 2)), t)
        t += 1 / 30
    return t


def test_backs_off_until_a_remembered_obstacle_in_the_blind_zone_is_in_view() -> None:
    nav = Navigator(line_graph(), NavigatorConfig(backoff_time_s=0.5))
    nav.set_goal(5, np.array([-1.5, 0.0, 0.0]))
    t = drive_in(nav, -1.5, 0.0)  # it came from there: the way back is its trail
    # Seen 0.4 m ahead (closer than the camera's 0.8 m minimum range: the next frames see nothing).
    wall = np.array([[0.4, y] for y in np.linspace(-1, 1, 41)])
    cmd = nav.command(np.zeros(3), wall, t)
    assert cmd.state == "recovering" and cmd.velocity[0] < 0
    x, t0 = 0.0, t
    while cmd.state == "recovering" and t < 20:
        t += 1 / 30
        x += cmd.velocity[0] / 30
        cmd = nav.command(np.array([x, 0.0, 0.0]), np.zeros((0, 2)), t)
    # It backed off past backoff_time_s, until the wall's place came into view (and was
    # seen empty), then drove on.
    assert t - t0 > 0.5 and 0.4 - x > DepthCamera().min_range_m + DepthCamera().forward_m
    assert cmd.state == "driving"


def test_slows_down_to_stop_before_an_obstacle() -> None:
    nav = Navigator(line_graph())
    nav.set_goal(5, np.zeros(3))
    wall = np.array([[0.6, y] for y in np.linspace(-3, 3, 121)])  # open length 0.2 m: v = sqrt(2 a 0.15)
    v = np.hypot(*nav.command(np.zeros(3), wall, 0.0).velocity[:2])
    assert 0.0 < v < 0.75


def test_no_progress_triggers_back_off_and_replan() -> None:
    # No trail to back off along and the plan straight ahead: without look_back_m it
    # turns towards the plan for backoff_time_s (tests/test_navigator_recovery.py looks back).
    nav = Navigator(line_graph(), NavigatorConfig(stuck_time_s=2.0, look_back_m=0.0))
    nav.set_goal(5, np.zeros(3))
    states = [nav.command(np.zeros(3), np.zeros((0, 2)), t).state for t in np.arange(0, 5, 1 / 30)]
    assert "recovering" in states and nav.recoveries >= 1 and nav.replans >= 1
    i = states.index("recovering")
    assert states[i + 1] == "recovering"  # backs off for a while, then drives again
    assert states[-1] == "driving"


def test_arrives() -> None:
    nav = Navigator(line_graph())
    nav.set_goal(2, np.zeros(3))
    assert nav.command(np.array([4.1, 0.1, 0.0]), np.zeros((0, 2)), 0.0).state == "arrived"


def test_nearest_reachable_node_skips_nodes_behind_walls() -> None:
    walls = np.array([[1.0, -1.0, 1.0, 1.0]])
    nav = Navigator(line_graph(), walls=walls)
    # Node 1 at (2, 0) is nearer to (1.2, 0) than node 0 ... but node 0 is behind the wall.
    assert nav.nearest_reachable_node(np.array([0.9, 0.0])) == 0
    assert nav.nearest_reachable_node(np.array([1.1, 0.0])) == 1


def test_bad_config() -> None:
    with pytest.raises(InputError, match="lookahead_m"):
        NavigatorConfig(lookahead_m=0.0)
    assert math.isfinite(NavigatorConfig().cruise_speed_mps)


def test_obstacle_memory_keeps_points_out_of_view_and_refreshes_points_in_view() -> None:
    nav = Navigator(line_graph(), NavigatorConfig(memory_s=2.0, memory_beside_s=0.0, shadow_m=0.0))
    nav.set_goal(5, np.zeros(3))
    person = np.array([[2.0, 0.0]])  # 2 m ahead: in view
    assert len(nav.surroundings.remember(np.zeros(3), person, 0.0)) == 1
    # Next frame the camera sees the same place and the person is gone: forgotten.
    assert len(nav.surroundings.remember(np.zeros(3), np.zeros((0, 2)), 0.1)) == 0
    # A point beside the robot (out of view) persists until memory_s, then is dropped.
    nav.surroundings.remember(np.zeros(3), np.array([[0.0, 0.6]]), 0.2)
    kept = nav.surroundings.remember(np.array([0.5, 0.0, 0.0]), np.zeros((0, 2)), 1.0)
    np.testing.assert_allclose(kept, [[-0.5, 0.6]], atol=0.03)  # in the new robot frame
    assert len(nav.surroundings.remember(np.array([0.5, 0.0, 0.0]), np.zeros((0, 2)), 2.5)) == 0


def test_obstacle_memory_keeps_what_stands_beside_the_robot_while_it_is_near() -> None:
    nav = Navigator(line_graph(), NavigatorConfig(memory_s=2.0, memory_beside_s=10.0, memory_beside_m=1.0, shadow_m=0.0))
    nav.set_goal(5, np.zeros(3))
    nav.surroundings.remember(np.zeros(3), np.array([[0.0, 0.6]]), 0.0)
    # 0.78 m from the robot, out of view: kept past memory_s, until memory_beside_s.
    kept = nav.surroundings.remember(np.array([0.5, 0.0, 0.0]), np.zeros((0, 2)), 9.9)
    np.testing.assert_allclose(kept, [[-0.5, 0.6]], atol=0.03)
    assert len(nav.surroundings.remember(np.array([0.5, 0.0, 0.0]), np.zeros((0, 2)), 10.1)) == 0
    # Once the robot has moved away from it, memory_s alone holds.
    nav.surroundings.remember(np.zeros(3), np.array([[0.0, 0.6]]), 20.0)
    assert len(nav.surroundings.remember(np.array([0.9, 0.0, 0.0]), np.zeros((0, 2)), 23.0)) == 0
    assert len(nav.surroundings.remember(np.array([0.5, 0.0, 0.0]), np.zeros((0, 2)), 23.1)) == 1  # near again


def test_obstacle_memory_takes_what_hides_behind_a_seen_face_as_occupied() -> None:
    """A sensed point's shadow: cells every memory_cell_m behind it along the camera's
    sight line, up to shadow_m; the camera looking there again replaces them."""
    cfg = NavigatorConfig(memory_s=2.0, shadow_m=0.3, memory_cell_m=0.05)
    nav = Navigator(line_graph(), cfg)
    cam_x = nav.camera.forward_m
    got = nav.surroundings.remember(np.zeros(3), np.array([[1.5, 0.0]]), 0.0)
    want = np.array([[1.5 + 0.05 * j, 0.0] for j in range(7)])
    np.testing.assert_allclose(got[np.argsort(got[:, 0])], want, atol=1e-9)
    # Off the camera's axis the shadow runs along the sight line from the camera.
    nav = Navigator(line_graph(), cfg)
    p = np.array([1.4, 0.4])  # 19 degrees off the camera's axis: in the replaced region
    got = nav.surroundings.remember(np.zeros(3), p[None], 0.0)
    u = (p - [cam_x, 0.0]) / np.hypot(p[0] - cam_x, p[1])
    ideal = p + np.outer(0.05 * np.arange(7), u)
    # On the 5 cm grid: every ideal point has its cell remembered.
    cells = {(round(x / 0.05), round(y / 0.05)) for x, y in got}
    assert cells == {(round(x / 0.05), round(y / 0.05)) for x, y in ideal}
    # The camera looks at that place again and sees it clear: the shadow is gone.
    assert len(nav.surroundings.remember(np.zeros(3), np.zeros((0, 2)), 0.1)) == 0


def test_obstacle_memory_keeps_one_point_per_cell_with_its_latest_time() -> None:
    """Against a dict of cells: every sensed cell once, stamped with the last time seen."""
    rng = np.random.default_rng(3)
    nav = Navigator(line_graph(), NavigatorConfig(memory_s=100.0, shadow_m=0.0))
    cell = nav.cfg.memory_cell_m
    seen: dict[tuple[int, int], float] = {}
    pose = np.array([-1.0, 0.5, 0.0])
    for k in range(5):
        # Points behind the robot (never in view), some cells repeated across frames.
        pts = np.column_stack([rng.uniform(-1.5, -0.2, 300), rng.uniform(-1.0, 1.0, 300)])
        pts = np.round(pts / (2 * cell)) * (2 * cell)
        nav.surroundings.remember(pose, pts, float(k))
        for x, y in pts + pose[:2]:
            seen[(round(x / cell), round(y / cell))] = float(k)
    got = {(round(x / cell), round(y / cell)): t for (x, y), t in zip(nav.surroundings._mem, nav.surroundings._mem_t, strict=True)}
    assert len(got) == len(nav.surroundings._mem) == len(seen)
    assert got == seen


def test_map_points_are_the_walls_near_the_robot_in_the_robot_frame() -> None:
    walls = np.array([[-5.0, 1.0, 5.0, 1.0], [-5.0, -3.0, 5.0, -3.0]])
    nav = Navigator(line_graph(), walls=walls)
    # Facing +y: the wall y = 1 is 1 m ahead (robot x); the wall y = -3 is out of reach.
    p = nav.surroundings.map_points(np.array([0.0, 0.0, math.pi / 2]), 1.5)
    assert len(p) > 10
    np.testing.assert_allclose(p[:, 0], 1.0, atol=1e-9)
    assert np.all(np.hypot(p[:, 0], p[:, 1]) < 1.5) and p[:, 1].min() < -1.0 and p[:, 1].max() > 1.0
    assert np.max(np.diff(np.sort(p[:, 1]))) <= 0.03 + 1e-9


def test_backs_off_away_from_a_wall_behind_it_and_not_into_one() -> None:
    """Recovery backs off straight back when that is clear, sideways-back when a wall is
    right behind one side, and not at all when boxed in (walls from the map, unseen).
    (The map's check alone: no trail, ``trail_s = 0``; tests/test_navigator_recovery.py
    has the trail.)"""
    cfg = NavigatorConfig(stuck_time_s=0.5, trail_s=0.0)
    clear = Navigator(line_graph(), cfg, walls=np.zeros((0, 4)))
    v = clear.recovery.backoff_velocity(np.zeros(3), np.zeros((0, 2)), 0.0)
    np.testing.assert_allclose(v, [-cfg.backoff_speed_mps, 0.0, 0.0], atol=1e-12)
    # A wall 0.4 m behind, across: straight back is blocked; so is everything within 75 degrees.
    behind = Navigator(line_graph(), cfg, walls=np.array([[-0.4, -3.0, -0.4, 3.0]]))
    np.testing.assert_allclose(behind.recovery.backoff_velocity(np.zeros(3), np.zeros((0, 2)), 0.0), 0.0)
    # A door frame's end 0.35 m behind-left: back off to the right-back instead.
    frame = Navigator(line_graph(), cfg, walls=np.array([[-0.35, 0.2, -3.0, 0.2]]))
    v = frame.recovery.backoff_velocity(np.zeros(3), np.zeros((0, 2)), 0.0)
    assert v[0] < 0 and v[1] < 0 and math.hypot(v[0], v[1]) == pytest.approx(cfg.backoff_speed_mps)
    # A remembered obstacle right in front does not stop it backing away.
    v = clear.recovery.backoff_velocity(np.zeros(3), np.array([[0.32, 0.0]]), 0.0)
    assert v[0] < 0


def test_backs_through_a_door_only_near_its_centre() -> None:
    """A 0.92 m door leaves 0.16 m beside the robot; the map's jambs are placed through a
    pose estimate that is a few cm off, so the robot backs straight through only within
    ``backoff_clearance_m`` of the door's centre. 0.1 m off it, with its back in the
    doorway, straight back would pass the jamb 5.8 cm beyond its radius: it backs off
    towards the centre instead."""
    cfg = NavigatorConfig(stuck_time_s=0.5, trail_s=0.0)
    half = 0.46
    door = np.array([[-3.0, 0.0, -half, 0.0], [half, 0.0, 3.0, 0.0]])
    nav = Navigator(line_graph(), cfg, walls=door)
    centred = nav.recovery.backoff_velocity(np.array([0.0, 0.3, math.pi / 2]), np.zeros((0, 2)), 0.0)
    np.testing.assert_allclose(centred, [-cfg.backoff_speed_mps, 0.0, 0.0], atol=1e-12)  # robot frame
    off = nav.recovery.backoff_velocity(np.array([0.1, 0.3, math.pi / 2]), np.zeros((0, 2)), 0.0)
    assert off[0] < 0.0 and off[1] > 0.2 * cfg.backoff_speed_mps  # back and to its left: world south-west
    # The jamb (0.46, 0) is kept beyond the robot radius plus the clearance over 0.4 m.
    u = np.array([-off[1], off[0]]) / np.hypot(off[0], off[1])  # world axes
    rel = np.array([half - 0.1, -0.3])
    along = np.clip(rel @ u, 0.0, cfg.backoff_check_m)
    assert np.hypot(*(rel - along * u)) >= nav.avoid.robot_radius_m + cfg.backoff_clearance_m


def test_in_camera_view_is_the_cone_between_the_ranges() -> None:

    cam = DepthCamera()
    ang = np.radians([0.0, 0.0, 0.0, 28.0, 30.0, -28.0, 180.0])
    rng = np.array([2.0, 0.5, 4.5, 2.0, 2.0, 2.0, 2.0])
    got = in_camera_view(rng * np.cos(ang), rng * np.sin(ang), cam)
    assert got.tolist() == [True, False, False, True, False, True, False]
    # The memory's narrower test: 28 degrees is outside 90% of the +-28.9 degree view.
    assert not in_camera_view(np.array([2 * math.cos(math.radians(28))]), np.array([2 * math.sin(math.radians(28))]), cam, 0.9)[0]


def l_graph() -> NavGraph:
    """Straight east 6 m (nodes every 2 m), then a right-angle turn north for 4 m."""
    pts = [(0.0, 0.0), (2.0, 0.0), (4.0, 0.0), (6.0, 0.0), (6.0, 2.0), (6.0, 4.0)]
    nodes = tuple(NavNode(id=i, x=x, y=y) for i, (x, y) in enumerate(pts))
    return NavGraph(nodes=nodes, edges=tuple(NavEdge(s0_id=i, s1_id=i + 1) for i in range(5)))


def test_takes_the_plans_corners_slowly() -> None:
    """With corner_speed_mps 0.4: full speed on the straight (collinear nodes are no corners); from 2 m before the
    right-angle corner the limit falls linearly to corner_speed_mps, which holds from
    1 m before to 0.3 m past it; then full speed again. The commanded speed follows."""
    nav = Navigator(l_graph(), NavigatorConfig(corner_speed_mps=0.4))
    nav.set_goal(5, np.zeros(3))
    cfg = nav.cfg
    assert nav.plan.corner_speed_limit(0.0) == math.inf and nav.plan.corner_speed_limit(3.9) == math.inf
    assert nav.plan.corner_speed_limit(4.5) == pytest.approx(cfg.corner_speed_mps + 0.5 * (cfg.cruise_speed_mps - cfg.corner_speed_mps))
    for s in (5.0, 5.5, 6.0, 6.29):
        assert nav.plan.corner_speed_limit(s) == pytest.approx(cfg.corner_speed_mps)
    assert nav.plan.corner_speed_limit(6.31) == math.inf
    speed = lambda x: float(np.hypot(*nav.command(np.array([x, 0.0, 0.0]), np.zeros((0, 2)), 0.0).velocity[:2]))  # noqa: E731
    assert speed(2.0) == pytest.approx(0.75) and speed(5.2) == pytest.approx(cfg.corner_speed_mps)
    # A shallow bend (30 degrees) is no corner; corner_speed_mps = 0 turns it off.
    bend = NavGraph(
        nodes=(NavNode(id=0, x=0.0, y=0.0), NavNode(id=1, x=3.0, y=0.0), NavNode(id=2, x=3.0 + 3.0 * math.cos(0.5), y=3.0 * math.sin(0.5))),
        edges=(NavEdge(s0_id=0, s1_id=1), NavEdge(s0_id=1, s1_id=2)),
    )
    nav = Navigator(bend, NavigatorConfig(corner_speed_mps=0.4))
    nav.set_goal(2, np.zeros(3))
    assert nav.plan.corner_speed_limit(2.5) == math.inf
    nav = Navigator(l_graph(), NavigatorConfig(corner_speed_mps=0.0))  # 0 = off
    nav.set_goal(5, np.zeros(3))
    assert nav.plan.corner_speed_limit(5.5) == math.inf
    with pytest.raises(InputError, match="corner_speed_mps"):
        NavigatorConfig(corner_speed_mps=-0.1)


def test_honours_the_edges_max_speed() -> None:
    """The edge from x = 4 to 6 says 0.5 m/s (a door): the limit holds from lookahead_m
    before it until the robot's back (robot_radius_m) has left it; the command follows."""
    g = line_graph()
    edges = tuple(NavEdge(s0_id=e.s0_id, s1_id=e.s1_id, has_door=e.s0_id == 2, max_speed=0.5 if e.s0_id == 2 else 0.75) for e in g.edges)
    nav = Navigator(NavGraph(nodes=g.nodes, edges=edges))
    nav.set_goal(5, np.zeros(3))
    assert nav.plan.edge_speed_limit(1.0) == pytest.approx(0.75) and nav.plan.edge_speed_limit(3.1) == pytest.approx(0.75)
    for s in (3.3, 5.0, 6.2):
        assert nav.plan.edge_speed_limit(s) == pytest.approx(0.5)
    assert nav.plan.edge_speed_limit(6.4) == pytest.approx(0.75)
    speed = lambda n, x: float(np.hypot(*n.command(np.array([x, 0.0, 0.0]), np.zeros((0, 2)), 0.0).velocity[:2]))  # noqa: E731
    assert speed(nav, 1.0) == pytest.approx(0.75) and speed(nav, 5.0) == pytest.approx(0.5)
    # Planned the other way round, the same edge limits too.
    nav.set_goal(0, np.array([10.0, 0.0, math.pi]))
    assert nav.plan.edge_speed_limit(5.0) == pytest.approx(0.5)
    off = Navigator(NavGraph(nodes=g.nodes, edges=edges), NavigatorConfig(edge_speed_limits=False))
    off.set_goal(5, np.zeros(3))
    assert speed(off, 5.0) == pytest.approx(0.75)
    # max_speed 0 in a map file means no limit, not a robot that never moves.
    zero = tuple(NavEdge(s0_id=e.s0_id, s1_id=e.s1_id, max_speed=0.0) for e in g.edges)
    unlimited = Navigator(NavGraph(nodes=g.nodes, edges=zero))
    unlimited.set_goal(5, np.zeros(3))
    assert unlimited.plan.edge_speed_limit(5.0) == math.inf and speed(unlimited, 5.0) == pytest.approx(0.75)


def test_map_points_cache_matches_a_fresh_selection() -> None:
    """The wall points near the robot are cached and re-selected only after it has
    moved; along a random walk they equal those of a navigator without a cache."""
    rng = np.random.default_rng(5)
    walls = rng.uniform(-4.0, 4.0, size=(60, 4))
    nav = Navigator(line_graph(), walls=walls)
    xy = np.zeros(2)
    for _ in range(300):
        xy = xy + rng.normal(0.0, 0.15, 2)
        pose = np.array([*xy, rng.uniform(-math.pi, math.pi)])
        for r in (0.7, 1.6):
            got = nav.surroundings.map_points(pose, r)
            want = Navigator(line_graph(), walls=walls).surroundings.map_points(pose, r)
            np.testing.assert_allclose(np.sort(got, axis=0), np.sort(want, axis=0))
            assert np.all(np.hypot(got[:, 0], got[:, 1]) < r)


def test_map_walls_the_camera_cannot_see_steer_the_robot_off_them() -> None:
    """A wall 0.33 m to the right, beside the robot where the camera does not look: its
    map points block the straight direction (within robot radius + map_clearance_m), so
    the robot steers left, away from it. Without the map layer it drives straight on,
    and a wall farther than the clearance changes nothing. (The lane shift, off there,
    would move the carrot off that wall too.)"""
    wall = np.array([[-2.0, -0.33, 3.0, -0.33]])
    nav = Navigator(line_graph(), walls=wall)
    nav.set_goal(5, np.zeros(3))
    pts = nav.surroundings.map_blind_spots(np.zeros(3))
    assert len(pts) and np.all(np.hypot(pts[:, 0], pts[:, 1]) <= nav.cfg.map_blind_spots_m + 1e-9)
    cmd = nav.command(np.zeros(3), np.zeros((0, 2)), 0.0)
    assert cmd.state == "driving" and cmd.theta_star_rad > math.radians(5)
    off = Navigator(line_graph(), NavigatorConfig(map_blind_spots_m=0.0, lane_shift_m=0.0), walls=wall)
    off.set_goal(5, np.zeros(3))
    assert off.command(np.zeros(3), np.zeros((0, 2)), 0.0).theta_star_rad == pytest.approx(0.0)
    far = Navigator(line_graph(), walls=np.array([[-2.0, -0.45, 3.0, -0.45]]))
    far.set_goal(5, np.zeros(3))
    assert far.command(np.zeros(3), np.zeros((0, 2)), 0.0).theta_star_rad == pytest.approx(0.0)


def test_walls_seen_before_count_with_the_map_in_the_blind_spots() -> None:
    """The same wall 0.33 m to the right, now unknown to the map but given as points seen
    before (a relocalization's scan): the robot steers away from it as from a mapped
    wall. Given to one frame, they are not kept for the next."""
    wall = np.column_stack([np.linspace(-2.0, 3.0, 201), np.full(201, -0.33)])
    nav = Navigator(line_graph(), NavigatorConfig(lane_shift_m=0.0), walls=np.zeros((0, 4)))
    nav.set_goal(5, np.zeros(3))
    cmd = nav.command(np.zeros(3), np.zeros((0, 2)), 0.0, seen=wall)
    assert cmd.state == "driving" and cmd.theta_star_rad > math.radians(5)
    pts = nav.surroundings.map_points(np.zeros(3), 1.0)
    assert len(pts) and np.all(np.hypot(pts[:, 0], pts[:, 1]) < 1.0)
    nav2 = Navigator(line_graph(), NavigatorConfig(lane_shift_m=0.0), walls=np.zeros((0, 4)))
    nav2.set_goal(5, np.zeros(3))
    assert nav2.command(np.zeros(3), np.zeros((0, 2)), 0.0).theta_star_rad == pytest.approx(0.0)
    nav.command(np.zeros(3), np.zeros((0, 2)), 0.1)
    assert len(nav.surroundings.map_points(np.zeros(3), 1.0)) == 0


def test_heads_for_a_direction_without_a_plan_or_the_map() -> None:
    """head_for: a robot that does not know where it is drives along a heading in its
    odometry's frame. Facing away, it turns in place; facing it, it drives at cruise
    speed whatever the map says (the pose is not on the map: a mapped wall beside it
    is ignored); a wall it sees ahead blocks it; points of its scan beside it, where
    the camera does not look, steer it off them as the map's walls would."""
    mapped = np.array([[-2.0, -0.33, 3.0, -0.33]])  # where the camera does not look
    nav = Navigator(line_graph(), walls=mapped)
    cmd = nav.head_for(np.zeros(3), math.pi, np.zeros((0, 2)), 0.0)
    assert cmd.state == "turning" and np.hypot(*cmd.velocity[:2]) == 0.0 and abs(cmd.velocity[2]) > 1.0
    cmd = nav.head_for(np.zeros(3), 0.0, np.zeros((0, 2)), 0.0)
    assert cmd.state == "driving" and cmd.theta_star_rad == pytest.approx(0.0)
    np.testing.assert_allclose(cmd.velocity, [0.75, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(cmd.carrot, [nav.cfg.lookahead_m, 0.0])
    wall = np.array([[0.4, y] for y in np.linspace(-3, 3, 121)])
    blocked = Navigator(line_graph(), NavigatorConfig(memory_s=0.0), walls=mapped)
    cmd = blocked.head_for(np.zeros(3), 0.0, wall, 0.0)
    assert cmd.state == "blocked" and np.hypot(*cmd.velocity[:2]) == 0.0
    beside = np.column_stack([np.linspace(-2.0, 3.0, 201), np.full(201, -0.33)])
    cmd = Navigator(line_graph()).head_for(np.zeros(3), 0.0, np.zeros((0, 2)), 0.0, seen=beside)
    assert cmd.state == "driving" and cmd.theta_star_rad > math.radians(5)
    far = np.column_stack([np.linspace(-2.0, 3.0, 201), np.full(201, -0.45)])
    assert Navigator(line_graph()).head_for(np.zeros(3), 0.0, np.zeros((0, 2)), 0.0, seen=far).theta_star_rad == pytest.approx(0.0)


def test_slows_down_passing_close_to_an_obstacle() -> None:
    """With proximity_speed_mps 0.4, a person 0.55 m to the side, 1 m ahead: outside the
    avoidance corridor (0.4 m), so the robot drives straight on, but within
    proximity_gap_m of it, so at proximity_speed_mps. At 0.8 m abeam, or behind the robot, full speed."""
    speed = lambda nav, pts: float(np.hypot(*nav.command(np.zeros(3), np.array(pts), 0.0).velocity[:2]))  # noqa: E731
    nav = Navigator(line_graph(), NavigatorConfig(memory_s=0.0, proximity_speed_mps=0.4))
    nav.set_goal(5, np.zeros(3))
    person = [[1.0, -0.55], [1.0, -0.6], [1.05, -0.55]]
    assert nav.steering.obstacle_near_path(np.array(person), 0.0)
    assert speed(nav, person) == pytest.approx(nav.cfg.proximity_speed_mps)
    assert speed(nav, [[1.0, -0.8]]) == pytest.approx(0.75)
    assert speed(nav, [[-0.5, -0.5]]) == pytest.approx(0.75)
    assert NavigatorConfig().proximity_speed_mps == 0.4  # on by default
    off = Navigator(line_graph(), NavigatorConfig(memory_s=0.0, proximity_speed_mps=0.0))  # 0 = off
    off.set_goal(5, np.zeros(3))
    assert speed(off, person) == pytest.approx(0.75)


def test_a_robot_with_no_way_back_waits_instead_of_hanging_in_a_back_off() -> None:
    """Something too close for the camera right ahead, a wall right behind: the robot
    cannot back off. It waits (blocked), recovers when stuck, and never stays in a
    motionless back-off for longer than a recovery's back-off time. It had stayed
    'recovering' without moving for as long as the obstacle was there. (The pose is held:
    a look back would turn for ever, look_back_m = 0.)"""
    wall = np.array([[-0.34, -2.0, -0.34, 2.0]])
    nav = Navigator(line_graph(), NavigatorConfig(look_back_m=0.0), walls=wall)
    pose = np.zeros(3)
    nav.set_goal(5, pose)
    ahead = np.array([[0.45, y] for y in np.linspace(-0.3, 0.3, 13)])  # 0.23 m from the camera
    run, longest, states = 0, 0, set()
    for k in range(600):  # 20 s
        cmd = nav.command(pose, ahead, k / 30.0)
        states.add(cmd.state)
        assert np.allclose(cmd.velocity[:2], 0.0)
        run = run + 1 if cmd.state == "recovering" else 0
        longest = max(longest, run)
    assert "blocked" in states and nav.recoveries >= 1
    assert longest <= nav.cfg.backoff_time_s * 30 + 1


def test_after_a_long_back_off_the_stuck_clock_starts_again() -> None:
    """A stuck recovery whose back-off runs on to max_backoff_s (something following the
    robot, too close to see) is not followed straight by another recovery: the stuck
    clock had run on through the back-off."""
    nav = Navigator(line_graph())
    pose = np.zeros(3)
    nav.set_goal(5, np.array([-1.5, 0.0, 0.0]))
    t = drive_in(nav, -1.5, 0.0)  # the trail it may back off along
    blocker = np.array([[0.5, y] for y in np.linspace(-0.35, 0.35, 15)])  # robot frame, every frame
    k = int(round(t * 30))
    while nav.recoveries == 0:
        nav.command(pose, blocker, k / 30.0)
        k += 1
    t_end = k / 30.0 + nav.cfg.max_backoff_s + 1.0
    while k / 30.0 < t_end:
        nav.command(pose, blocker, k / 30.0)
        k += 1
    assert nav.recoveries == 1


def test_backs_off_clear_of_furniture_seen_long_before() -> None:
    """A box seen 0.6 m ahead, then the robot turns round: 10 s later (the avoidance's
    memory has long forgotten it) the box is right behind, and the back-off does not
    go straight into it; with a 2 s back-off memory it does."""
    box = np.array([[0.6, y] for y in np.linspace(-0.2, 0.2, 9)])
    for backoff_memory_s, straight in ((30.0, False), (2.0, True)):
        # The memory's check alone (no trail: trail_s = 0; it would not back off there either).
        nav = Navigator(line_graph(), NavigatorConfig(backoff_memory_s=backoff_memory_s, trail_s=0.0, memory_beside_s=0.0))
        nav.set_goal(5, np.zeros(3))
        nav.surroundings.remember(np.zeros(3), box, 0.0)
        turned = np.array([0.0, 0.0, math.pi])
        assert len(nav.surroundings.remember(turned, np.zeros((0, 2)), 10.0)) == 0  # forgotten by the avoidance
        v = nav.recovery.backoff_velocity(turned, np.zeros((0, 2)), 10.0)
        assert np.allclose(v[:2], [-0.15, 0.0]) == straight, v


def test_the_navigator_sees_through_its_camera() -> None:
    # A point 1.0 m ahead of the camera is in view of the Kinect (0.8-4 m), not of a
    # camera that sees nothing closer than 1.5 m: there it is a blind spot.
    x = np.array([1.0])
    assert in_camera_view(x, np.zeros(1), DepthCamera())[0]
    assert not in_camera_view(x, np.zeros(1), DepthCamera(min_range_m=1.5))[0]
    walls = np.array([[1.3, -1.0, 1.3, 1.0]])  # 1.08 m ahead of the camera
    near = Navigator(line_graph(), NavigatorConfig(map_blind_spots_m=1.5), walls=walls)
    far = Navigator(line_graph(), NavigatorConfig(map_blind_spots_m=1.5), walls=walls, camera=DepthCamera(min_range_m=1.5))
    pose = np.array([0.0, 0.0, 0.0])
    ahead = lambda pts: pts[np.abs(pts[:, 1]) < 0.05]  # noqa: E731
    assert len(ahead(near.surroundings.map_blind_spots(pose))) == 0
    assert len(ahead(far.surroundings.map_blind_spots(pose))) > 0


# A corridor (y in [5.25, 7.4]) with a 0.906 m door in its south wall at x = 23.661,
# into a room below: the shipped building's door where a robot turning off the corridor
# once touched the west jamb.
DOOR_X, DOOR_HALF = 23.661, 0.453
DOOR_WALLS = np.array(
    [
        [18.0, 7.4, 28.0, 7.4],
        [18.0, 5.25, DOOR_X - DOOR_HALF, 5.25],
        [DOOR_X + DOOR_HALF, 5.25, 28.0, 5.25],
        [21.4, 5.25, 21.4, 2.0],
        [26.0, 5.25, 26.0, 2.0],
        [21.4, 2.0, 26.0, 2.0],
    ]
)


def door_graph(max_clearance: float = DOOR_HALF, has_door: bool = True) -> NavGraph:
    pts = [(19.0, 6.325), (DOOR_X, 6.325), (DOOR_X, 5.25), (DOOR_X, 4.5), (DOOR_X, 3.0)]
    nodes = tuple(NavNode(id=i, x=x, y=y) for i, (x, y) in enumerate(pts))
    door = {(1, 2), (2, 3)}
    edges = tuple(
        NavEdge(s0_id=i, s1_id=i + 1, has_door=has_door and (i, i + 1) in door, max_clearance=max_clearance if (i, i + 1) in door else 1.075)
        for i in range(4)
    )
    return NavGraph(nodes=nodes, edges=edges)


def drive_by_the_door(nav: Navigator, pose: np.ndarray, goal: int, pose_error: tuple[float, float] = (0.0, 0.0)) -> tuple[np.ndarray, list[str]]:
    """Drive from ``pose`` to the node ``goal`` among :data:`DOOR_WALLS`, the navigator
    seeing the walls through its camera and believing the pose ``pose_error`` off;
    returns the true poses (one per frame, 30 Hz) and the navigator's states."""
    world = wall_points(DOOR_WALLS, 0.03)
    nav.set_goal(goal, pose)
    poses, states, t, dt = [pose], [], 0.0, 1.0 / 30.0
    while t < 30.0:
        belief = pose + np.array([*pose_error, 0.0])
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rx, ry = world[:, 0] - pose[0], world[:, 1] - pose[1]
        bx, by = c * rx + s * ry, -s * rx + c * ry
        seen = in_camera_view(bx - nav.camera.forward_m, by, nav.camera)
        cmd = nav.command(belief, np.column_stack([bx[seen], by[seen]]), t)
        states.append(cmd.state)
        if cmd.state == "arrived":
            break
        v = cmd.velocity
        pose = pose + dt * np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]])
        poses.append(pose)
        t += dt
    assert states[-1] == "arrived", f"the robot did not reach node {goal}"
    return np.array(poses), states


def through_the_door(nav: Navigator, pose_error: tuple[float, float] = (0.0, 0.0)) -> float:
    """Drive from the corridor's west end through the door into the room; returns the
    closest the robot's edge came to a wall (m)."""
    poses, _ = drive_by_the_door(nav, np.array([19.0, 6.325, 0.0]), 4, pose_error)
    return float(point_segment_distance(poses[:, :2], DOOR_WALLS).min()) - nav.avoid.robot_radius_m


def test_enters_a_door_straight_on_a_short_carrot() -> None:
    """Turning off the corridor 1 m before the door, the 0.8 m carrot cuts the corner and
    the robot enters the door off its centre, nearer the west jamb; the short carrot
    before and on narrow edges lines it up first, near the door's centre (0.153 m beside
    the robot), so that a pose estimate 6 cm east of the truth (the map's jambs placed 6
    cm west of the real ones) still clears the jamb."""
    east = (0.06, 0.0)
    centred = through_the_door(Navigator(door_graph(), walls=DOOR_WALLS))
    assert centred > 0.12
    assert through_the_door(Navigator(door_graph(), walls=DOOR_WALLS), east) > 0.06
    off = NavigatorConfig(narrow_lookahead_m=0.0)
    assert through_the_door(Navigator(door_graph(), off, walls=DOOR_WALLS)) < centred - 0.03
    assert through_the_door(Navigator(door_graph(), off, walls=DOOR_WALLS), east) < 0.03
    # A narrow edge not flagged as a door is taken the same way: its clearance says so.
    assert through_the_door(Navigator(door_graph(has_door=False), walls=DOOR_WALLS)) == pytest.approx(centred)
    # On a graph whose edges are wide, the carrot stays long everywhere.
    wide = Navigator(door_graph(max_clearance=1.0, has_door=False))
    wide.set_goal(4, np.array([19.0, 6.325, 0.0]))
    assert {wide.plan.lookahead(s) for s in np.linspace(0.0, 8.0, 81)} == {0.8}
    # The plan: 4.661 m along the corridor to the corner, where the door's edges begin,
    # 1.075 m to the door, then 0.75 m to the room's node. The jambs come within 0.55 m
    # (the robot's radius and the slack) of the edges from 0.31 m before the door to
    # 0.31 m past it: the carrot is short from 2.75 m before that until 0.3 m after.
    nav = Navigator(door_graph(), walls=DOOR_WALLS)
    nav.set_goal(4, np.array([19.0, 6.325, 0.0]))
    door, reach = 4.661 + 1.075, math.sqrt(0.55**2 - DOOR_HALF**2)
    assert nav.plan.lookahead(door - reach - 2.75 - 0.02) == 0.8 and nav.plan.lookahead(door - reach - 2.75 + 0.02) == 0.3
    assert nav.plan.lookahead(door + reach + 0.3 - 0.02) == 0.3 and nav.plan.lookahead(door + reach + 0.3 + 0.02) == 0.8
    # Without the map's walls the whole of each narrow edge is narrow.
    blind = Navigator(door_graph())
    blind.set_goal(4, np.array([19.0, 6.325, 0.0]))
    assert blind.plan.lookahead(4.661 - 2.75 - 0.05) == 0.8 and blind.plan.lookahead(4.661 - 2.75 + 0.05) == 0.3
    assert blind.plan.lookahead(door + 0.75 + 0.25) == 0.3 and blind.plan.lookahead(door + 0.75 + 0.35) == 0.8
    with pytest.raises(InputError, match="narrow_lookahead_m"):
        NavigatorConfig(narrow_lookahead_m=1.0)


def test_a_plan_starting_on_its_first_edge_does_not_double_back() -> None:
    """A robot that reached the door's node 0.3 m short of it (within the arrival radius)
    and is sent back along the corridor stands on the door's edge: the plan runs from
    there along that edge, not forward to the door's node (the nearest) and back, where
    the carrot on the doubled-back line jumped behind the robot and it turned to and fro.
    Leaving the door on the short carrot, Eq. 5 scores open lengths up to 1 m, so the
    corridor's two ways (open 4 m, 35 degrees off the carrot) do not out-score the way
    out towards the corridor's far wall."""
    nav = Navigator(door_graph(), walls=DOOR_WALLS)
    start = np.array([DOOR_X, 5.25 + 0.3, -math.pi / 2])  # facing the room
    assert nav.set_goal(0, start) == pytest.approx(0.775 + 4.661)
    np.testing.assert_allclose(nav.path[1], [DOOR_X, 6.325])
    poses, states = drive_by_the_door(nav, start, 0)
    assert poses[:, 1].min() > start[1] - 0.02  # never towards the door
    assert "recovering" not in states
    assert states.count("turning") < 90  # turning round (about 55 frames), then once
    uncapped = Navigator(door_graph(), NavigatorConfig(narrow_horizon_m=0.0), walls=DOOR_WALLS)
    assert drive_by_the_door(uncapped, start, 0)[1].count("turning") > 2 * states.count("turning")
    # Off the edge's line by more than its clearance, the plan goes by its first node.
    assert nav.set_goal(0, np.array([DOOR_X + 0.6, 5.55, 0.0])) > 0.775 + 4.661 + 0.5


def _hall() -> tuple[NavGraph, np.ndarray]:
    """A 24 x 14 m hall: a straight edge across its middle, where the camera sees no wall
    for 18.5 of its 20 m either way, and a way round along a wall, 1.5 m from it, 31 m
    long and never blind."""
    walls = np.array([[0, 0, 24, 0], [24, 0, 24, 14], [24, 14, 0, 14], [0, 14, 0, 0]], float)
    pts = {1: (2.0, 7.0), 2: (22.0, 7.0), 3: (2.0, 1.5), 4: (22.0, 1.5)}
    nodes = tuple(NavNode(id=i, x=x, y=y) for i, (x, y) in pts.items())
    edges = tuple(NavEdge(s0_id=a, s1_id=b) for a, b in [(1, 2), (1, 3), (3, 4), (4, 2)])
    return NavGraph(nodes=nodes, edges=edges), walls


def test_plans_keep_walls_in_the_cameras_range_where_a_detour_allows() -> None:
    graph, walls = _hall()
    start = np.array([2.0, 7.0, 0.0])
    nav = Navigator(graph, walls=walls)
    nav.set_goal(2, start, 0.0)
    assert nav.plan_nodes == [1, 3, 4, 2]  # 31 m along the wall, not 18.5 blind metres
    # Shortest paths without the coastal cost, or without the walls to measure it by.
    for shortest in (Navigator(graph, NavigatorConfig(coastal_weight=0.0), walls=walls), Navigator(graph)):
        shortest.set_goal(2, start, 0.0)
        assert shortest.plan_nodes == [1, 2]
    # A blind metre costs 1 + coastal_weight metres: the 11 m detour pays from a weight of
    # 11 / 18.5; at 0.2 the hall is crossed.
    cheap = Navigator(graph, NavigatorConfig(coastal_weight=0.2), walls=walls)
    cheap.set_goal(2, start, 0.0)
    assert cheap.plan_nodes == [1, 2]


def test_coastal_config_is_checked() -> None:
    with pytest.raises(InputError, match="navigator.coastal_weight"):
        NavigatorConfig(coastal_weight=-1.0)
    with pytest.raises(InputError, match="navigator.coastal_range_m"):
        NavigatorConfig(coastal_range_m=0.0)


def test_a_phantom_point_in_a_narrow_door_holds_the_robot_only_for_a_while() -> None:
    """One point sensed once in a 0.906 m door, 8 cm off its centre, as it comes closer
    than the camera sees (the edge of a person walking across, who walks on): the robot
    (0.8 m wide with its margin) cannot pass it, and inside the camera's blind zone only
    a look at its place from farther away clears it. Turning off the corridor 1.5 m before the door, the robot's trail leads sideways
    and its back-off ends short of that; the memory lets the point go after
    ``memory_blind_s`` and the robot goes through the door. Kept until seen again, the
    point holds the robot in front of the door past a minute."""

    def drive(cfg: NavigatorConfig) -> tuple[str, float]:
        nav = Navigator(door_graph(), cfg, walls=DOOR_WALLS)
        world = wall_points(DOOR_WALLS, 0.03)
        phantom = np.array([DOOR_X - 0.08, 5.25])
        pose = np.array([DOOR_X - 1.5, 6.325, 0.0])
        nav.set_goal(4, pose)
        state, t, dt, sensed = "", 0.0, 1.0 / 30.0, False
        while t < 60.0 and state != "arrived":
            c, s = math.cos(pose[2]), math.sin(pose[2])
            rx, ry = world[:, 0] - pose[0], world[:, 1] - pose[1]
            bx, by = c * rx + s * ry, -s * rx + c * ry
            obs = np.column_stack([bx, by])[in_camera_view(bx - nav.camera.forward_m, by, nav.camera)]
            px, py = phantom - pose[:2]
            ph = np.array([c * px + s * py, -s * px + c * py])
            if not sensed and abs(ph[1]) < 0.3 and math.hypot(ph[0] - nav.camera.forward_m, ph[1]) < nav.camera.min_range_m + 0.12:
                obs, sensed = np.vstack([obs, ph]), True
            cmd = nav.command(pose, obs, t)
            state, v = cmd.state, cmd.velocity
            pose = pose + dt * np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]])
            t += dt
        assert sensed
        return state, t

    state, t = drive(NavigatorConfig())
    assert state == "arrived" and t < 30.0
    assert drive(NavigatorConfig(memory_blind_s=1000.0))[0] != "arrived"
