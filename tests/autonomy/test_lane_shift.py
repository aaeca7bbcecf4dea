"""The navigator's lane shift (``lane_shift_m``): the carrot moves sideways to pass what
stands on the plan's line, against a brute-force reading of its definition."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
from autonomy.navigation.config import NavigatorConfig
from autonomy.navigation.navigator import Navigator


def line_graph() -> NavGraph:
    """A straight plan along the x axis, 0 to 10 m."""
    nodes = tuple(NavNode(id=i, x=float(2 * i), y=0.0) for i in range(6))
    return NavGraph(nodes=nodes, edges=tuple(NavEdge(s0_id=i, s1_id=i + 1) for i in range(5)))


def corridor(half_width: float) -> np.ndarray:
    return np.array([[-2.0, -half_width, 12.0, -half_width], [-2.0, half_width, 12.0, half_width]])


def person(x: float, y: float, radius: float = 0.22, n: int = 15) -> np.ndarray:
    """The half of a standing person's outline facing a robot at the origin."""
    a = np.linspace(0.5 * math.pi, 1.5 * math.pi, n)
    return np.column_stack([x + radius * np.cos(a), y + radius * np.sin(a)])


def nav_at(walls: np.ndarray | None = None, **cfg) -> Navigator:
    """A navigator planning along the x axis from the origin to (10, 0)."""
    nav = Navigator(line_graph(), NavigatorConfig(memory_s=0.0, **cfg), walls=walls)
    nav.set_goal(5, np.zeros(3))
    return nav


def brute_offset(nav: Navigator, pose: np.ndarray, sensed: np.ndarray, walls: np.ndarray | None) -> tuple[list[float], float]:
    """The clear offsets of the definition, by loops over offsets and points (the plan is
    the x axis, so plan and world frames coincide; the robot faces +x or not)."""
    cfg, r = nav.cfg, nav.avoid.radius_m
    c, s = math.cos(pose[2]), math.sin(pose[2])
    world = [(pose[0] + c * px - s * py, pose[1] + s * px + c * py) for px, py in sensed]
    s0 = min(max(pose[0], 0.0), 10.0)
    reach = min(cfg.lane_check_m, 10.0 - s0)
    # The map's walls that count: their points within reach of the robot (the walls run
    # along the plan here, so only their ends' reach matters), inside the window ahead.
    wall_lat = []
    if walls is not None:
        for x0, y0, x1, y1 in walls:
            xs = np.linspace(x0, x1, 2001)
            ys = np.linspace(y0, y1, 2001)
            near = (np.hypot(xs - pose[0], ys - pose[1]) < reach + cfg.lane_shift_m + r) & (xs - s0 > -r) & (xs - s0 < reach)
            wall_lat.extend(ys[near].tolist())
    wall_gap = nav.avoid.robot_radius_m + cfg.map_clearance_m
    clear = []
    for k in range(-18, 19):
        o = 0.05 * k
        ok = all(not (-r < x - s0 < reach and abs(y - o) < r) for x, y in world)
        ok = ok and all(abs(y - o) >= wall_gap for y in set(wall_lat))
        if ok:
            clear.append(o)
    return clear, s0


def test_a_person_in_the_middle_of_a_corridor_is_passed_on_the_side_the_robot_is_on() -> None:
    """Person (radius 0.22 m) on the plan 1.5 m ahead: offsets closer than 0.22 + 0.4 m
    (avoidance radius) are blocked, so the carrot shifts 0.65 m, to the left with the
    robot a little left of the plan, to the right with it a little right or right on it
    (people step to their right, the robot's left)."""
    walls = corridor(1.2)
    for y, side in ((0.02, 1.0), (-0.02, -1.0), (0.0, -1.0)):
        nav = nav_at(walls)
        pose = np.array([0.0, y, 0.0])
        pts = person(1.5, 0.0) - pose[:2]
        assert math.isclose(nav.steering.lane_offset(nav.plan, pose, pts, 0.0), side * 0.65)
        cmd = nav.command(pose, pts, 0.0)
        # Towards the shifted carrot: turning first (look_first), the way it will go.
        assert side * cmd.desired_rad > math.radians(20) and side * cmd.velocity[2] > 0


def test_the_first_choice_is_the_clear_offset_nearest_the_robot() -> None:
    """Person 0.2 m left of the plan, robot 0.1 m left: offsets from -0.42 to 0.82 m are
    blocked. Left of the person needs 0.85 m (0.75 m from the robot), right of them
    -0.45 m (0.55 m away), so it passes on the right, though it is left of the plan."""
    nav = nav_at(corridor(1.5))
    pose = np.array([0.0, 0.1, 0.0])
    assert math.isclose(nav.steering.lane_offset(nav.plan, pose, person(1.5, 0.2) - pose[:2], 0.0), -0.45)


def test_the_side_chosen_is_kept_until_the_obstacle_is_passed() -> None:
    walls = corridor(1.2)
    nav = nav_at(walls)
    pts = person(1.5, 0.0)
    assert nav.steering.lane_offset(nav.plan, np.array([0.0, 0.05, 0.0]), pts - [0.0, 0.05], 0.0) > 0
    # Drifted right of the plan on the way, it still passes left.
    pose = np.array([0.5, -0.1, 0.0])
    assert nav.steering.lane_offset(nav.plan, pose, pts - pose[:2], 0.5) > 0
    # Left blocked now (something beside the left wall), it takes the right.
    pose = np.array([0.6, 0.0, 0.0])
    both = np.vstack([pts, person(1.8, 0.75)]) - pose[:2]
    assert nav.steering.lane_offset(nav.plan, pose, both, 0.6) < 0
    # Past the person (more than the avoidance radius behind), back on the plan.
    pose = np.array([2.2, 0.6, 0.0])
    assert nav.steering.lane_offset(nav.plan, pose, pts - pose[:2], 2.2) == 0.0


def test_no_shift_where_the_line_is_clear_nothing_is_clear_or_it_is_off() -> None:
    # Clear: a person 0.7 m off the plan.
    nav = nav_at(corridor(1.2))
    assert nav.steering.lane_offset(nav.plan, np.zeros(3), person(1.5, 0.7), 0.0) == 0.0
    # Nothing clear: a 1.8 m corridor, a person in its middle (0.62 + 0.35 > 0.9).
    nav = nav_at(corridor(0.9))
    assert nav.steering.lane_offset(nav.plan, np.zeros(3), person(1.5, 0.0), 0.0) == 0.0
    # Farther ahead than lane_check_m: not yet.
    nav = nav_at(corridor(1.2))
    assert nav.steering.lane_offset(nav.plan, np.zeros(3), person(2.8, 0.0), 0.0) == 0.0
    # Off.
    nav = nav_at(corridor(1.2), lane_shift_m=0.0)
    assert nav.steering.lane_offset(nav.plan, np.zeros(3), person(1.5, 0.0), 0.0) == 0.0
    cmd = nav.command(np.zeros(3), person(1.5, 0.0), 0.0)
    assert abs(cmd.desired_rad) < 1e-9


def test_a_wall_beside_the_plan_shifts_it_off_the_wall() -> None:
    """A map wall 0.3 m right of the plan (inside robot radius + map_clearance_m) moves
    the carrot 0.05 m left, the nearest clear offset."""
    nav = nav_at(np.array([[-1.0, -0.3, 12.0, -0.3]]))
    assert math.isclose(nav.steering.lane_offset(nav.plan, np.zeros(3), np.zeros((0, 2)), 0.0), 0.05)


@settings(max_examples=60, deadline=None)
@given(
    y=st.floats(-0.3, 0.3),
    heading=st.floats(-0.6, 0.6),
    s_robot=st.floats(0.0, 6.0),
    half_width=st.floats(0.8, 1.6),
    obs=st.lists(st.tuples(st.floats(-1.0, 4.0), st.floats(-1.4, 1.4)), min_size=0, max_size=6),
)
@example(y=0.0, heading=0.0, s_robot=0.0, half_width=1.21, obs=[(1.5, 0.0)])
def test_lane_offset_matches_its_definition(y, heading, s_robot, half_width, obs) -> None:
    walls = corridor(half_width)
    nav = nav_at(walls)
    # Exactly at a clearance, the rounding of the frame change decides: not a case to test.
    offs = 0.05 * np.arange(-18, 19)
    r, gap = nav.avoid.radius_m, nav.avoid.robot_radius_m + nav.cfg.map_clearance_m
    for oy in [o[1] for o in obs]:
        assume(np.all(np.abs(np.abs(oy - offs) - r) > 1e-6))
    assume(np.all(np.abs(np.abs(half_width - np.abs(offs)) - gap) > 1e-6))
    assume(all(abs(abs(ox - s_robot) - (r if ox < s_robot else nav.cfg.lane_check_m)) > 1e-6 for ox, _ in obs))
    pose = np.array([s_robot, y, heading])
    world = np.array(obs, dtype=float).reshape(-1, 2)
    c, s = math.cos(heading), math.sin(heading)
    rel = world - pose[:2]
    sensed = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]]) if len(rel) else rel
    got = nav.steering.lane_offset(nav.plan, pose, sensed, s_robot)
    clear, _ = brute_offset(nav, pose, sensed, walls)
    if 0.0 in clear or not clear:
        assert got == 0.0
        return
    assert any(math.isclose(got, o, abs_tol=1e-9) for o in clear)
    first = min(clear, key=lambda o: (abs(o - y), o > 0))
    side = 1.0 if first > 0 else -1.0
    same = [o for o in clear if o * side > 0]
    want = min(same or clear, key=abs)
    assert math.isclose(got, want, abs_tol=1e-6)
