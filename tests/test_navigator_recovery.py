"""The navigator's recovery: re-planning round a blocked corridor, back-offs only along
the robot's own trail, looking round, pose jumps.

A kinematic robot (the command integrated exactly, the estimate is the truth) on a
hand-made ring of corridors; the depth camera is stood in for by the points of the walls
and of a hand-placed box that lie in the camera's view (no occlusion).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.common.geometry import wrap_angles
from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
from autonomy.maps.planner import NoPathError, astar, edge_key
from autonomy.navigation.config import NavigatorConfig
from autonomy.navigation.navigator import Navigator
from autonomy.navigation.surroundings import in_camera_view, wall_points
from autonomy.perception.camera import KINECT_V1

RATE_HZ = 30.0
ROBOT_R = 0.3

# A ring of 2 m corridors round a block: the bottom corridor (y in [-1, 1]) from A to C
# is 8 m; the way round by the top corridor (y in [2, 4]) 14 m.
A, B, C, D, E = 0, 1, 2, 3, 4
NODES = {A: (0.0, 0.0), B: (4.0, 0.0), C: (8.0, 0.0), D: (0.0, 3.0), E: (8.0, 3.0)}
WALLS = np.array(
    [
        [-1.0, -1.0, 9.0, -1.0], [9.0, -1.0, 9.0, 4.0], [9.0, 4.0, -1.0, 4.0], [-1.0, 4.0, -1.0, -1.0],  # outside
        [1.0, 1.0, 7.0, 1.0], [7.0, 1.0, 7.0, 2.0], [7.0, 2.0, 1.0, 2.0], [1.0, 2.0, 1.0, 1.0],  # the block
    ]
)
BOX = (2.6, 3.0, -1.0, 1.0)
"""A box (x0, x1, y0, y1) right across the bottom corridor, not in the map."""


def ring_graph() -> NavGraph:
    nodes = tuple(NavNode(id=i, x=x, y=y) for i, (x, y) in NODES.items())
    edges = tuple(NavEdge(s0_id=a, s1_id=b) for a, b in ((A, B), (B, C), (A, D), (D, E), (E, C)))
    return NavGraph(nodes=nodes, edges=edges)


def box_outline(box: tuple[float, float, float, float], step: float = 0.02) -> np.ndarray:
    x0, x1, y0, y1 = box
    return wall_points(np.array([[x0, y0, x1, y0], [x1, y0, x1, y1], [x1, y1, x0, y1], [x0, y1, x0, y0]]), step)


def box_gap(xy: np.ndarray, box: tuple[float, float, float, float]) -> float:
    """Distance from a point to the box (0 inside)."""
    x0, x1, y0, y1 = box
    return math.hypot(max(x0 - xy[0], 0.0, xy[0] - x1), max(y0 - xy[1], 0.0, xy[1] - y1))


def sense(pose: np.ndarray, world_pts: np.ndarray, near_field: bool = False) -> np.ndarray:
    """The world points the camera sees from the pose, robot frame; ``near_field``: also
    those in its field of view closer than its minimum range (as the near field tells)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rx, ry = world_pts[:, 0] - pose[0], world_pts[:, 1] - pose[1]
    bx, by = c * rx + s * ry, -s * rx + c * ry
    keep = in_camera_view(bx - KINECT_V1.forward_m, by, KINECT_V1)
    if near_field:
        keep |= (np.abs(np.arctan2(by, bx - KINECT_V1.forward_m)) < 0.5 * KINECT_V1.fov_h_rad) & (bx > 0.0)
    return np.column_stack([bx[keep], by[keep]])


def step(pose: np.ndarray, v: np.ndarray) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dt = 1.0 / RATE_HZ
    return np.array([pose[0] + dt * (c * v[0] - s * v[1]), pose[1] + dt * (s * v[0] + c * v[1]), pose[2] + dt * v[2]])


def drive(nav: Navigator, pose: np.ndarray, goal: int, seconds: float, box=BOX, t0: float = 0.0, box_until: float = math.inf):
    """Drive to ``goal`` (the box there until ``box_until``); returns (final pose, time,
    arrived, nodes of every plan, closest approach of the robot's edge to the box)."""
    walls_only = wall_points(WALLS, 0.03)
    world_pts = np.vstack([walls_only, box_outline(box)]) if box is not None else walls_only
    nav.set_goal(goal, pose, t0)
    plans = {tuple(nav.plan_nodes)}
    closest = math.inf
    t = t0
    while t < t0 + seconds:
        if t >= box_until:
            box, world_pts = None, walls_only
        cmd = nav.command(pose, sense(pose, world_pts), t)
        plans.add(tuple(nav.plan_nodes))
        if cmd.state == "arrived":
            return pose, t, True, plans, closest
        pose = step(pose, cmd.velocity)
        if box is not None:
            closest = min(closest, box_gap(pose[:2], box) - ROBOT_R)
        t += 1.0 / RATE_HZ
    return pose, t, False, plans, closest


def test_astar_leaves_out_excluded_edges_either_way_round() -> None:
    g = ring_graph()
    assert astar(g, A, C) == [A, B, C]
    assert astar(g, A, C, excluded=[(B, A)]) == [A, D, E, C]  # given either way round
    assert astar(g, A, C, excluded={edge_key(B, C)}) == [A, D, E, C]
    with pytest.raises(NoPathError):
        astar(g, A, C, excluded=[(A, B), (D, E)])


@pytest.mark.parametrize("blocked_wait_s", [3.0, 100.0])
def test_a_box_across_the_corridor_is_passed_the_other_way_round(blocked_wait_s: float) -> None:
    """Blocked by the box on the short way, the robot marks the bottom corridor's edge
    blocked and reaches the goal the long way round, without touching the box: after
    blocked_wait_s without progress (re-planning at once, no recovery), or, with that
    wait longer than stuck_time_s, at the stuck recovery. With the blocked edges off it
    re-plans the same way for ever (its plans never leave the bottom corridor) and does
    not arrive."""
    start = np.array([0.0, 0.0, 0.0])
    # Without the box's shadow, which reaches within the avoidance radius of B and so
    # marks B-C too: the edges the box itself stands on.
    nav = Navigator(ring_graph(), NavigatorConfig(blocked_wait_s=blocked_wait_s, shadow_m=0.0), walls=WALLS)
    pose, t, arrived, plans, closest = drive(nav, start, C, 90.0)
    assert arrived and np.hypot(*(pose[:2] - NODES[C])) < nav.cfg.arrival_radius_m
    assert closest > 0.0  # never touched the box
    assert edge_key(A, B) in nav.blocked and nav.blocked_edges == 1
    assert nav.recoveries == (0 if blocked_wait_s < nav.cfg.stuck_time_s else 1)
    assert edge_key(D, E) not in nav.blocked and edge_key(B, C) not in nav.blocked  # the box is on A-B only
    assert any(D in p and E in p for p in plans)
    assert nav.plan_nodes[-3:] == [D, E, C]
    assert t > 14.0 / nav.cfg.cruise_speed_mps  # it went the long way
    if blocked_wait_s > nav.cfg.stuck_time_s:
        return
    off = Navigator(ring_graph(), NavigatorConfig(blocked_edge_s=0.0), walls=WALLS)
    pose, _, arrived, plans, closest = drive(off, start, C, 60.0)
    assert not arrived and off.recoveries >= 3 and off.blocked_edges == 0 and not off.blocked
    assert all(D not in p and E not in p for p in plans)
    assert closest > 0.0 and pose[0] < BOX[0]


def test_a_long_way_round_is_taken_only_once_the_block_has_held() -> None:
    """The way round is 6 m longer than the bottom corridor; with re-plans longer by more
    than 3 m put off, the robot waits for a box that is gone after 6 s (a person who
    walks on) and takes the short way, nothing marked; a box that stays is gone round
    once it has held ``long_detour_wait_s``. At once, without the put-off."""
    start = np.array([0.0, 0.0, 0.0])
    patient = NavigatorConfig(long_detour_m=3.0)
    nav = Navigator(ring_graph(), patient, walls=WALLS)
    _, t_short, arrived, plans, closest = drive(nav, start, C, 60.0, box_until=6.0)
    assert arrived and closest > 0.0 and not nav.blocked
    assert all(D not in p and E not in p for p in plans)
    hasty = Navigator(ring_graph(), walls=WALLS)
    _, _, arrived, plans, _ = drive(hasty, start, C, 60.0, box_until=6.0)
    assert arrived and any(D in p and E in p for p in plans)  # gone round, the box gone
    # The box stays: the long way, after the wait.
    nav = Navigator(ring_graph(), patient, walls=WALLS)
    _, t_wait, arrived, plans, closest = drive(nav, start, C, 90.0)
    _, t_hasty, _, _, _ = drive(Navigator(ring_graph(), walls=WALLS), start, C, 90.0)
    assert arrived and closest > 0.0 and edge_key(A, B) in nav.blocked and nav.plan_nodes[-3:] == [D, E, C]
    assert t_wait > t_hasty + 0.5 * patient.long_detour_wait_s
    with pytest.raises(InputError, match="long_detour_wait_s"):
        NavigatorConfig(long_detour_wait_s=-1.0)


def test_blocked_edges_expire_and_are_forgotten_when_they_leave_no_path() -> None:
    cfg = NavigatorConfig(blocked_edge_s=60.0)
    nav = Navigator(ring_graph(), cfg, walls=WALLS)
    pose, t, arrived, _, _ = drive(nav, np.array([0.0, 0.0, 0.0]), C, 90.0)
    assert arrived
    marked = dict(nav.blocked)
    assert edge_key(A, B) in marked
    t_mark = marked[edge_key(A, B)] - cfg.blocked_edge_s
    # Back to A: still blocked before the mark expires, the plan goes round by the top ...
    nav.set_goal(A, pose, t_mark + cfg.blocked_edge_s - 0.5)
    assert nav.plan_nodes == [C, E, D, A]
    # ... and after it expired the bottom corridor is planned again (the box was taken away).
    nav.set_goal(A, pose, t_mark + cfg.blocked_edge_s + 0.5)
    assert nav.plan_nodes == [C, B, A] and not nav.blocked
    # Marks that leave no path at all are forgotten: plan with the whole graph and wait.
    nav.blocked.update({edge_key(B, C): math.inf, edge_key(E, C): math.inf})
    nav.set_goal(C, np.array([0.0, 0.0, 0.0]), 0.0)
    assert nav.plan_nodes == [A, B, C] and not nav.blocked
    # Expired marks also leave the set viewers read as frames go by.
    nav.blocked[edge_key(D, E)] = 1.0
    nav.command(np.array([0.0, 0.0, 0.0]), np.zeros((0, 2)), 1.5)
    assert not nav.blocked


def corner_graph() -> NavGraph:
    """East along y = 0 to the origin, then a 110 degree turn to the left."""
    turn = math.radians(110.0)
    pts = [(-4.0, 0.0), (0.0, 0.0), (4.0 * math.cos(turn), 4.0 * math.sin(turn))]
    nodes = tuple(NavNode(id=i, x=x, y=y) for i, (x, y) in enumerate(pts))
    return NavGraph(nodes=nodes, edges=(NavEdge(s0_id=0, s1_id=1), NavEdge(s0_id=1, s1_id=2)))


def _corner_then_blocked(cfg: NavigatorConfig, box: tuple[float, float, float, float], seconds: float = 10.0):
    """Drive east along y = 0 to the corner (the trail), turn 110 degrees left, and feed a
    blocker right in front, too close for the camera, every frame; returns the distance
    translated, the closest approach to ``box`` and the positions."""
    blocker = np.array([[0.45, y] for y in np.linspace(-0.3, 0.3, 13)])  # robot frame
    nav = Navigator(corner_graph(), cfg)
    nav.set_goal(2, np.array([-3.0, 0.0, 0.0]))
    t = 0.0
    for x in np.arange(-3.0, 0.0, 0.025):  # the way in: its trail
        nav.command(np.array([x, 0.0, 0.0]), np.zeros((0, 2)), t)
        t += 1.0 / RATE_HZ
    pose = np.array([0.0, 0.0, math.radians(110.0)])
    closest, moved, track = math.inf, 0.0, []
    for _ in range(int(seconds * RATE_HZ)):
        cmd = nav.command(pose, blocker, t)
        moved += math.hypot(cmd.velocity[0], cmd.velocity[1]) / RATE_HZ
        pose = step(pose, cmd.velocity)
        closest = min(closest, box_gap(pose[:2], box) - ROBOT_R)
        track.append(pose[:2].copy())
        t += 1.0 / RATE_HZ
    return moved, closest, np.array(track)


def test_backs_off_only_along_its_trail() -> None:
    """The robot drove east to a corner and turned 110 degrees left; then something
    stands right in front of it, too close for the camera. Behind it now lies space it
    never saw nor drove through, where a box stands that no memory holds. The old rule
    (trail_s = 0: map walls and memory only) backs straight into the box; with the trail
    the robot does not translate at all (it waits turning towards its plan). With the
    lane shift on, the robot turns a little towards a shifted carrot, until a direction
    within 75 degrees of its back runs along the trail: it backs off that way only (if
    at all: here a few centimetres, until the next step would leave the trail's band)."""
    back = math.radians(110.0) + math.pi
    centre = np.array([0.6 * math.cos(back), 0.6 * math.sin(back)])  # 0.6 m behind the robot
    box = (centre[0] - 0.2, centre[0] + 0.2, centre[1] - 0.2, centre[1] + 0.2)
    assert box_gap(np.zeros(2), box) > ROBOT_R + 0.05
    moved, closest, _ = _corner_then_blocked(NavigatorConfig(trail_s=0.0, lane_shift_m=0.0), box)
    assert closest < 0.0, "the old rule was expected to back into the box"
    moved, closest, _ = _corner_then_blocked(NavigatorConfig(lane_shift_m=0.0), box)
    assert moved == 0.0 and closest > 0.05
    moved, closest, track = _corner_then_blocked(NavigatorConfig(), box)
    assert closest > 0.05
    assert np.all(np.abs(track[:, 1]) < NavigatorConfig().trail_tolerance_m) and np.all(track[:, 0] <= 1e-9)


def _turned_round_and_blocked(cfg: NavigatorConfig, seconds: float = 25.0):
    """As at a waypoint reached through a doorway: the robot came east along y = 0 to
    x = -0.4 (its trail), turned round to go back west, and finds a person standing
    0.7 m ahead (near field). East of it, where it never drove, stands a box 0.85 m away.
    Returns the track (x, y, yaw per frame), the commands and the closest approach to
    the person and to the box."""
    walls = np.array([[-7.0, -1.0, 3.0, -1.0], [-7.0, 1.0, 3.0, 1.0]])
    nodes = (NavNode(id=0, x=-6.0, y=0.0), NavNode(id=1, x=-3.0, y=0.0), NavNode(id=2, x=-0.4, y=0.0))
    g = NavGraph(nodes=nodes, edges=(NavEdge(s0_id=0, s1_id=1), NavEdge(s0_id=1, s1_id=2)))
    person, box = (-1.5, -1.1, -0.3, 0.3), (0.45, 0.85, -0.5, 0.5)
    pts = np.vstack([wall_points(walls, 0.03), box_outline(person), box_outline(box)])
    nav = Navigator(g, cfg, walls=walls)
    nav.set_goal(2, np.array([-3.0, 0.0, 0.0]))
    t = 0.0
    for x in np.arange(-3.0, -0.4, 0.025):  # the way in, before the person stepped in behind
        pose = np.array([x, 0.0, 0.0])
        nav.command(pose, sense(pose, wall_points(walls, 0.03)), t)
        t += 1.0 / RATE_HZ
    pose = np.array([-0.4, 0.0, math.pi])
    nav.set_goal(0, pose, t)
    track, cmds, closest = [], [], [math.inf, math.inf]
    for _ in range(int(seconds * RATE_HZ)):
        cmd = nav.command(pose, sense(pose, pts, near_field=True), t)
        cmds.append(cmd.velocity.copy())
        pose = step(pose, cmd.velocity)
        track.append(pose.copy())
        closest = [min(closest[0], box_gap(pose[:2], person) - ROBOT_R), min(closest[1], box_gap(pose[:2], box) - ROBOT_R)]
        t += 1.0 / RATE_HZ
    return np.array(track), np.array(cmds), closest


def test_a_robot_that_may_not_back_off_looks_back_and_drives_away_seeing() -> None:
    """Blocked by a person right after turning round, with no trail behind it: the old
    rule (trail_s = 0) backs off blind into the box it never saw; without the look back
    the robot never moves east of where it turned (it waits for the person, who would
    wait for it); looking back, it turns round first (it translates only while facing
    east, the way back, or west, its plan), drives east until the box it now sees (the
    near field) blocks the way, and touches nothing."""
    track, _, closest = _turned_round_and_blocked(NavigatorConfig(trail_s=0.0))
    assert closest[1] < 0.0, "the old rule was expected to back into the box"
    track, cmds, closest = _turned_round_and_blocked(NavigatorConfig(look_back_m=0.0))
    assert track[:, 0].max() <= -0.4 + 1e-9 and min(closest) > 0.0  # never east of where it turned
    track, cmds, closest = _turned_round_and_blocked(NavigatorConfig())
    assert min(closest) > 0.0 and track[:, 0].max() > -0.1
    # Every move is where the camera looks, or back to where the robot has been.
    moving = np.hypot(cmds[:, 0], cmds[:, 1]) > 0
    before = np.vstack([[-0.4, 0.0, math.pi], track[:-1]])
    in_view = np.abs(np.arctan2(cmds[:, 1], cmds[:, 0])) <= 0.5 * KINECT_V1.fov_h_rad
    way_in = np.arange(-3.0, -0.4, 0.025)
    been = np.vstack([np.column_stack([way_in, np.zeros(len(way_in))]), before[:, :2]])
    for k in np.flatnonzero(moving & ~in_view):
        assert np.min(np.hypot(*(been[: len(way_in) + k] - track[k, :2]).T)) <= NavigatorConfig().trail_tolerance_m, k
    assert np.any(moving & (np.abs(wrap_angles(before[:, 2])) < math.radians(30.0)))  # drove facing east


def _on_polyline(q: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance of each point of ``q`` to the polyline ``line`` (brute force)."""
    a, d = line[:-1], np.diff(line, axis=0)
    rel = q[:, None, :] - a[None, :, :]
    f = np.clip((rel * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-12), 0.0, 1.0)
    return np.hypot(*(rel - f[..., None] * d).transpose(2, 0, 1)).min(axis=1)


def test_the_way_back_retraces_the_trail() -> None:
    """A trail east along y = 0, then a quarter circle left: the way back from its end
    runs along the circle (not straight back), is backoff_check_m long and lies on the
    trail; from a pose 0.15 m off the trail there is none; a trail older than trail_s
    counts no more; the way back ends where the footprints jump (a pose correction)."""
    nav = Navigator(corner_graph(), NavigatorConfig(trail_s=5.0))
    nav.set_goal(2, np.array([-3.0, 0.0, 0.0]))
    drove = [np.array([x, 0.0]) for x in np.arange(-2.0, 0.0, 0.025)]
    drove += [np.array([math.sin(a), 1.0 - math.cos(a)]) for a in np.arange(0.0, math.pi / 2, 0.025)]
    t = 0.0
    for xy in drove:
        nav.command(np.array([xy[0], xy[1], 0.0]), np.zeros((0, 2)), t)
        t += 1.0 / RATE_HZ
    pts = nav.trail_points()
    assert len(pts) > 40 and np.max(np.hypot(*np.diff(pts, axis=0).T)) < 0.08
    end = np.array([drove[-1][0], drove[-1][1], math.pi / 2])
    way = nav.retrace(end)
    np.testing.assert_allclose(way[0], end[:2])
    assert np.sum(np.hypot(*np.diff(way, axis=0).T)) == pytest.approx(NavigatorConfig().backoff_check_m)
    dense = np.vstack([np.linspace(way[k], way[k + 1], 10) for k in range(len(way) - 1)])
    assert _on_polyline(dense, np.vstack([pts, end[:2]])).max() < 1e-9
    # It follows the circle: 0.4 m back along a unit circle bends 23 degrees off straight back.
    assert way[-1][1] < end[1] - 0.35 and way[-1][0] < end[0] - 0.05
    assert len(nav.retrace(end + np.array([0.15, 0.0, 0.0]))) == 1
    # A stretch the robot did not drive (a pose correction of 0.3 m) ends the way back.
    nav.command(np.array([0.7, 1.0, 0.0]), np.zeros((0, 2)), t)
    nav.command(np.array([0.75, 1.0, 0.0]), np.zeros((0, 2)), t + 0.1)
    short = nav.retrace(np.array([0.75, 1.0, 0.0]))
    assert len(short) >= 2 and np.sum(np.hypot(*np.diff(short, axis=0).T)) < 0.1
    nav.command(np.array([0.75, 1.0, 0.0]), np.zeros((0, 2)), t + 6.0)  # standing still: the trail ages out
    assert len(nav.trail_points()) <= 1 and len(nav.retrace(end)) == 1


def _passed_unseen_then_blocked(cfg: NavigatorConfig, seconds: float = 8.0):
    """The robot drove east along y = 0 past a person standing 1 cm beside its edge (at
    a door jamb that hid them from the camera: nothing ever sensed), turned 12 degrees
    left towards its plan and finds something right ahead, too close for the camera.
    Returns the distance it backed off and the closest approach of its edge to the person."""
    nodes = (NavNode(id=0, x=-4.0, y=0.0), NavNode(id=1, x=0.0, y=0.0), NavNode(id=2, x=1.5, y=0.3))
    g = NavGraph(nodes=nodes, edges=(NavEdge(s0_id=0, s1_id=1), NavEdge(s0_id=1, s1_id=2)))
    person = (-0.9, -0.5, -ROBOT_R - 0.01 - 0.3, -ROBOT_R - 0.01)
    nav = Navigator(g, cfg)
    nav.set_goal(2, np.array([-3.0, 0.0, 0.0]))
    t = 0.0
    for x in np.arange(-3.0, 0.0, 0.025):  # the way in: its trail
        nav.command(np.array([x, 0.0, 0.0]), np.zeros((0, 2)), t)
        t += 1.0 / RATE_HZ
    blocker = np.array([[0.45, y] for y in np.linspace(-0.3, 0.3, 13)])  # robot frame, every frame
    pose = np.array([0.0, 0.0, math.radians(12.0)])
    closest, moved = math.inf, 0.0
    for _ in range(int(seconds * RATE_HZ)):
        cmd = nav.command(pose, blocker, t)
        moved += math.hypot(cmd.velocity[0], cmd.velocity[1]) / RATE_HZ
        pose = step(pose, cmd.velocity)
        closest = min(closest, box_gap(pose[:2], person) - ROBOT_R)
        t += 1.0 / RATE_HZ
    return moved, closest


def test_a_back_off_retraces_the_way_past_a_person_it_never_saw() -> None:
    """Backing off, the robot keeps to the space its body swept: a person whom the robot
    passed 1 cm clear, unseen, is passed 1 cm clear again. Straight back, 12 degrees off
    the way it came but within trail_tolerance_m (0.1 m) of its footprints over 0.4 m,
    touched them (as a back-off towards a door once did)."""
    moved, closest = _passed_unseen_then_blocked(NavigatorConfig())
    assert moved > 0.3
    assert closest > 0.005


def test_look_around_turns_in_place_and_a_pose_jump_clears_what_the_old_estimate_placed() -> None:
    cfg = NavigatorConfig(look_turn_rate_rad_s=0.6)
    nav = Navigator(ring_graph(), cfg, walls=WALLS)
    nav.set_goal(C, np.array([0.0, 0.0, 0.0]))
    cmd = nav.look_around(3.0)
    assert cmd.state == "looking" and cmd.velocity.tolist() == [0.0, 0.0, 0.6]
    # After looking for longer than stuck_time_s, no recovery on the next frame.
    assert nav.command(np.array([0.0, 0.0, 0.0]), np.zeros((0, 2)), 3.0 + 0.1).state != "recovering"
    t = 4.0
    for x in np.arange(0.0, 1.0, 0.025):
        nav.command(np.array([x, 0.0, 0.0]), np.array([[0.2, 0.7], [1.5, 0.0]]), t)
        t += 1.0 / RATE_HZ
    nav.steering._lane, nav.steering._side = 0.5, 1
    assert len(nav.trail_points()) > 10 and len(nav.surroundings._mem) > 0
    nav.blocked[edge_key(D, E)] = t + 100.0
    replans = nav.replans
    nav.pose_jumped(np.array([8.0, 3.0, 0.0]), t)
    assert len(nav.trail_points()) == 0 and len(nav.surroundings._mem) == 0 and len(nav.surroundings.remembered) == 0
    assert nav.steering._lane == 0.0 and nav.steering._side == 0
    assert nav.replans == replans + 1 and nav.plan_nodes[0] == E and nav.plan_nodes[-1] == C
    assert edge_key(D, E) in nav.blocked  # marks stay (they expire)
    nav.pose_jumped()  # without a pose: clears only
    assert nav.replans == replans + 1
    with pytest.raises(InputError, match="look_turn_rate_rad_s"):
        NavigatorConfig(look_turn_rate_rad_s=0.0)
    with pytest.raises(InputError, match="trail_tolerance_m"):
        NavigatorConfig(trail_tolerance_m=-0.1)
    with pytest.raises(InputError, match="blocked_edge_s"):
        NavigatorConfig(blocked_edge_s=float("nan"))


# -- the incident figure draws every body a contact names ---------------------------------


def _incident(bodies: list[str], people: list[list[float]] | None = None) -> dict:
    frame = {
        "t": 9.9, "truth": [2.0, 3.0, 0.0], "estimate": [2.0, 3.0, 0.0], "state": "driving", "cmd": [0.3, 0.0, 0.0],
        "desired_deg": 0.0, "theta_star_deg": 0.0, "open_m": 1.0, "n_obstacles": 0, "nearest_obstacle": None,
        "near_points": 0, "people": people or [],
    }
    return {"event": {"t": 10.0, "x": 2.0, "y": 3.0, "bodies": bodies, "heading_deg": 0.0}, "trace": [frame, frame]}


def test_the_incident_figure_draws_fault_placed_furniture_and_named_people(tmp_path) -> None:
    import warnings

    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from sim.experiments.blackbox import (
        _draw_furniture,
        _draw_tracks,
        footprints,
        render_incidents,
        undrawn_bodies,
    )
    from sim.simulator.actors import Furniture

    pieces = [Furniture("table", 1.0, 2.0, 0.5), (2.0, 3.6, math.pi / 2, (1.0, 0.4, 1.0))]  # the second placed by a fault
    drawn = footprints(pieces, {"door_0": (3.0, 3.0, 0.0, (0.05, 0.9))})
    assert [f["body"] for f in drawn] == ["furniture_0", "furniture_1", "door_0"]
    # The fault's box stands where it was given: yaw 90 degrees swaps length and width.
    ax = Figure().add_subplot()
    _draw_furniture(ax, drawn)
    xy = ax.patches[1].get_xy()[:4]
    np.testing.assert_allclose(np.sort(xy[:, 0]), [1.8, 1.8, 2.2, 2.2], atol=1e-4)  # yaw kept to 1e-4 rad
    np.testing.assert_allclose(np.sort(xy[:, 1]), [3.1, 3.1, 4.1, 4.1], atol=1e-4)
    assert [t.get_text() for t in ax.texts] == ["table 0", "box 1", "door_0"]
    # Every body the contacts name is drawn: no warning.
    inc = _incident(["furniture_1", "person_1", "world", "door_0"], people=[[0.0, 0.0], [8.0, 3.0]])
    assert undrawn_bodies(inc, drawn) == []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = render_incidents([inc], np.array([[0.0, 0.0, 4.0, 0.0]]), tmp_path / "i.png", furniture=pieces, boxes={"door_0": (3.0, 3.0, 0.0, (0.05, 0.9))})
    assert out is not None and out.stat().st_size > 0
    # A person the contact names is drawn even when the trace has them far off.
    ax = Figure().add_subplot()
    _draw_tracks(ax, inc["trace"], 2.0, 3.0, 0.22, {1})
    assert " p1" in [t.get_text() for t in ax.texts]
    ax = Figure().add_subplot()
    _draw_tracks(ax, inc["trace"], 2.0, 3.0, 0.22)
    assert " p1" not in [t.get_text() for t in ax.texts]  # 6 m away and not named: not drawn


def test_an_incident_naming_a_body_not_drawn_says_so(tmp_path) -> None:
    import matplotlib

    matplotlib.use("Agg")

    from sim.experiments.blackbox import footprints, render_incidents, undrawn_bodies

    pieces = [(1.0, 1.0, 0.0, (0.5, 0.5))]
    inc = _incident(["furniture_3", "person_0"])  # a piece not passed; a person the trace lacks
    assert undrawn_bodies(inc, footprints(pieces)) == ["furniture_3", "person_0"]
    with pytest.warns(RuntimeWarning, match="furniture_3, person_0"):
        render_incidents([inc], np.zeros((0, 4)), tmp_path / "i.png", furniture=pieces)
    with pytest.raises(InputError, match="furniture_0"):
        footprints([(1.0, 2.0)])


def test_an_incident_keeps_the_furniture_where_it_stood() -> None:
    """The flight recorder keeps the furniture's poses with a new incident (a fault's box
    may be taken away before the run ends); the panel draws those."""
    from sim.experiments.blackbox import FlightRecorder, undrawn_bodies

    rec = FlightRecorder(1.0, 30.0)
    rec.on_events([{"t": 1.0, "x": 0.0, "y": 0.0, "bodies": ["furniture_0"]}], furniture=[(0.5, 0.0, 0.0, (0.4, 2.0, 1.0))])
    rec.on_events([{"t": 2.0, "x": 0.0, "y": 0.0, "bodies": ["world"]}])
    assert rec.incidents[0]["furniture"] == [
        {"body": "furniture_0", "label": "box 0", "x": 0.5, "y": 0.0, "yaw": 0.0, "size": [0.4, 2.0]}
    ]
    assert "furniture" not in rec.incidents[1]
    assert undrawn_bodies(rec.incidents[0], rec.incidents[0]["furniture"]) == []


def test_blocking_points_are_those_on_the_plans_line_ahead() -> None:
    """Against a dense sampling of the plan: a sensed point counts when some point of the
    plan between the avoidance radius behind the robot's place on it and blocked_check_m
    ahead lies within the avoidance radius of it, unless a map wall explains it."""
    rng = np.random.default_rng(11)
    wall = np.array([[-1.0, -0.3, 9.0, -0.3]])  # a mapped wall 0.3 m right of the line
    nav = Navigator(ring_graph(), walls=wall)
    pose = np.array([1.0, 0.0, 0.4])
    nav.set_goal(C, np.array([0.0, 0.0, 0.0]))
    c, s = math.cos(pose[2]), math.sin(pose[2])
    world = np.column_stack([rng.uniform(-0.5, 3.5, 4000), rng.uniform(-1.0, 1.0, 4000)])
    rel = world - pose[:2]
    local = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])
    got = nav.route.blocking_points(nav.plan, pose, local, nav.surroundings)
    r, s0 = nav.avoid.radius_m, 1.0  # the plan runs along y = 0 from x = 0
    xs = np.arange(s0 - r, s0 + nav.cfg.blocked_check_m, 0.001)
    line = np.column_stack([xs, np.zeros(len(xs))])
    gap = np.hypot(world[:, None, 0] - line[None, :, 0], world[:, None, 1]).min(axis=1)
    by_wall = np.abs(world[:, 1] + 0.3) < nav.cfg.near_wall_tol_m
    clear_cut = (np.abs(gap - r) > 0.003) & (np.abs(np.abs(world[:, 1] + 0.3) - nav.cfg.near_wall_tol_m) > 0.003)
    want = (gap < r) & ~by_wall
    hit = np.zeros(len(world), dtype=bool)
    for p in got:
        hit |= np.all(np.abs(world - p) < 1e-9, axis=1)
    assert want.sum() > 300 and (by_wall & (gap < r)).sum() > 100
    assert np.array_equal(hit[clear_cut], want[clear_cut])


def test_in_a_dead_end_the_blocked_edges_change_nothing() -> None:
    """A box across the only corridor to the goal: marking its edge leaves no path, so
    the marks are forgotten and the robot waits and recovers exactly as with the blocked
    edges off, command for command (only the count of marks differs)."""
    walls = np.array([[-1.0, -1.0, 11.0, -1.0], [-1.0, 1.0, 11.0, 1.0], [-1.0, -1.0, -1.0, 1.0], [11.0, -1.0, 11.0, 1.0]])
    nodes = tuple(NavNode(id=i, x=2.0 * i, y=0.0) for i in range(6))
    line = NavGraph(nodes=nodes, edges=tuple(NavEdge(s0_id=i, s1_id=i + 1) for i in range(5)))
    box = (4.6, 5.0, -1.0, 1.0)
    world_pts = np.vstack([wall_points(walls, 0.03), box_outline(box)])
    runs = []
    for blocked_edge_s in (120.0, 0.0):
        nav = Navigator(line, NavigatorConfig(blocked_edge_s=blocked_edge_s), walls=walls)
        pose = np.array([0.0, 0.0, 0.0])
        nav.set_goal(5, pose, 0.0)
        cmds = []
        for k in range(int(30 * RATE_HZ)):
            cmd = nav.command(pose, sense(pose, world_pts), k / RATE_HZ)
            cmds.append(cmd.velocity.copy())
            pose = step(pose, cmd.velocity)
        runs.append((np.array(cmds), nav))
    (on, nav_on), (off, nav_off) = runs
    assert nav_on.blocked_edges >= 2 and not nav_on.blocked and nav_off.blocked_edges == 0
    assert nav_on.recoveries == nav_off.recoveries >= 2 and nav_on.replans == nav_off.replans
    np.testing.assert_array_equal(on, off)


# -- rounding furniture seen from one side -------------------------------------------


def _square(cx: float, cy: float, yaw: float, side: float) -> np.ndarray:
    """Corners (4, 2) of a square of ``side`` centred at (cx, cy), turned by ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    h = 0.5 * side
    loc = np.array([[h, h], [-h, h], [-h, -h], [h, -h]])
    return np.column_stack([cx + c * loc[:, 0] - s * loc[:, 1], cy + s * loc[:, 0] + c * loc[:, 1]])


def _faces(corners: np.ndarray, step: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """Points every ``step`` along a convex polygon's faces and each one's outward normal."""
    pts, normals = [], []
    centre = corners.mean(axis=0)
    for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True):
        d = b - a
        n = np.array([d[1], -d[0]]) / math.hypot(d[0], d[1])
        n = n if np.dot(n, 0.5 * (a + b) - centre) > 0 else -n
        f = np.linspace(0.0, 1.0, int(math.ceil(math.hypot(d[0], d[1]) / step)) + 1)[:-1]
        pts.append(a + f[:, None] * d)
        normals.append(np.repeat(n[None], len(f), axis=0))
    return np.vstack(pts), np.vstack(normals)


def _polygon_gap(xy: np.ndarray, corners: np.ndarray) -> float:
    """Distance from a point to a convex polygon's boundary, negative inside."""
    a, b = corners, np.roll(corners, -1, axis=0)
    d = b - a
    f = np.clip(((xy - a) * d).sum(axis=1) / (d * d).sum(axis=1), 0.0, 1.0)
    dist = float(np.min(np.hypot(*(xy - (a + f[:, None] * d)).T)))
    cross = d[:, 0] * (xy[1] - a[:, 1]) - d[:, 1] * (xy[0] - a[:, 0])
    inside = bool(np.all(cross > 0) or np.all(cross < 0))
    return -dist if inside else dist


def _round_the_chair(cfg: NavigatorConfig, seconds: float = 40.0) -> tuple[float, bool]:
    """West along y = 0, then a left turn to the south at the origin, past an unmapped
    0.45 m chair turned 45 degrees just south-east of the turn: the camera sees its north
    and east faces on the way in (a convex box's faces that face the camera, in view),
    never its west corner, which the turn sweeps the robot's left side towards. Returns
    the closest approach of the robot's edge to the chair and whether it arrived."""
    pts = [(6.0, 0.0), (0.0, 0.0), (0.0, -4.0)]
    graph = NavGraph(
        nodes=tuple(NavNode(id=i, x=x, y=y) for i, (x, y) in enumerate(pts)),
        edges=(NavEdge(s0_id=0, s1_id=1), NavEdge(s0_id=1, s1_id=2)),
    )
    corners = _square(0.6, -0.75, math.radians(45.0), 0.45)
    face_pts, normals = _faces(corners)
    nav = Navigator(graph, cfg)
    pose = np.array([6.0, 0.0, math.pi])
    nav.set_goal(2, pose, 0.0)
    closest, t = math.inf, 0.0
    while t < seconds:
        cam = pose[:2] + KINECT_V1.forward_m * np.array([math.cos(pose[2]), math.sin(pose[2])])
        facing = face_pts[((cam - face_pts) * normals).sum(axis=1) > 0.0]
        cmd = nav.command(pose, sense(pose, facing), t)
        if cmd.state == "arrived":
            return closest, True
        pose = step(pose, cmd.velocity)
        closest = min(closest, _polygon_gap(pose[:2], corners) - ROBOT_R)
        t += 1.0 / RATE_HZ
    return closest, False


def test_rounding_furniture_keeps_clear_of_the_side_the_camera_never_saw() -> None:
    """What hides behind the faces the camera saw counts as occupied (``shadow_m``):
    the robot turns round the chair clear of its unseen corner and arrives. Taking only
    the faces seen, it drives its side into that corner."""
    closest, arrived = _round_the_chair(NavigatorConfig())
    assert arrived and closest > 0.05
    closest, _ = _round_the_chair(NavigatorConfig(shadow_m=0.0, memory_beside_s=0.0))
    assert closest < 0.0
