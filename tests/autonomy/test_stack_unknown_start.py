"""Relocalization from an unknown start pose on the shipped corridor_loop map, without a
simulator: looking round, the map search, drives on the modes, drives to find walls,
and the near field while looking round (the map, the stack and the frames:
:mod:`tests.autonomy.stack_rig`)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from autonomy.common.geometry import (
    compose_pose,
    point_segment_distance,
    points_from_frame,
    points_in_frame,
    relative_pose,
    wrap_angle,
    wrap_angles,
)
from autonomy.stack import RobotStack, StackConfig, most_open_way
from tests.autonomy.stack_rig import (
    START,
    corridor_loop,
    drive,
    make_stack,
    render,
)
from tests.helpers import points_along


@pytest.fixture(scope="module")
def building():
    return corridor_loop()


# --------------------------------------------------------------------------- unknown start


def test_an_unknown_start_pose_looks_round_in_place(building) -> None:
    stack = make_stack(building, pose=None)
    assert stack.lost.relocalizing and stack.health_state == "relocalizing"
    assert stack.state.events[-1]["event"] == "lost" and "unknown" in stack.state.events[-1]["why"]
    for t in (0.0, 1.0, 30.0):  # no modes yet: it looks on, whatever the time
        cmd = stack.decide(t)
        assert cmd.state == "looking" and np.array_equal(cmd.velocity[:2], [0.0, 0.0])
        assert cmd.velocity[2] == pytest.approx(stack.cfg.navigator.look_turn_rate_rad_s)


@pytest.fixture(scope="module")
def found(building):
    """reset(None) at START, then the robot does what decide() says (perfect odometry),
    the camera seeing the map from the true pose, until it relocalizes (20 s at most)."""
    stack = make_stack(building, pose=None)
    fps = 10.0
    truth, inc, t, states = START.copy(), None, 0.0, []
    for k in range(int(20 * fps)):
        t = k / fps
        stack.perceive(render(building[1], truth))
        stack.localize(inc, t)
        if not stack.lost.relocalizing:
            break
        cmd = stack.decide(t)
        states.append(cmd.state)
        inc = cmd.velocity / fps
        truth = compose_pose(truth, inc)
    return stack, truth, t, states, fps


def test_an_unknown_start_pose_is_found_by_looking_round(found) -> None:
    stack, truth, t, states, _ = found
    done = [e for e in stack.state.events if e["event"] == "relocalized"]
    assert len(done) == 1, (t, stack.lost.last_search.reason if stack.lost.last_search else None)
    assert states[0] == "looking" and set(states) <= {"looking", "exploring", "turning", "driving"}
    err = relative_pose(truth, stack.state.pose)
    assert math.hypot(err[0], err[1]) < 0.15 and abs(wrap_angle(err[2])) < math.radians(3.0), err
    assert not stack.lost.relocalizing and stack.health_state == "ok"


def test_after_a_relocalization_the_robot_turns_in_place_before_driving_on(found) -> None:
    """CGR restarts around the accepted mode; the robot goes on turning in place for
    settle_s while it converges, then the navigator drives again."""
    stack, _, t, _, _ = found
    settle_s = stack.cfg.recovery.settle_s
    assert settle_s > 0
    for dt in (0.0, 0.5 * settle_s, settle_s - 0.05):
        cmd = stack.decide(t + dt)
        assert cmd.state == "settling" and np.array_equal(cmd.velocity[:2], [0.0, 0.0]) and cmd.velocity[2] > 0
    assert stack.decide(t + settle_s + 0.05).state not in ("settling", "looking")


def test_an_unknown_start_pose_is_found_while_still_turning_in_place(found) -> None:
    stack, _, t, states, fps = found
    rc = stack.cfg.recovery.relocalization
    assert set(states) == {"looking"}
    # Not before the sweep, then one search a second until confirmed.
    swept = math.radians(rc.min_sweep_deg) / stack.cfg.navigator.look_turn_rate_rad_s
    assert swept <= t <= swept + rc.confirmations * rc.search_every_s + 2 / fps


def test_a_mode_is_accepted_only_on_a_search_of_the_whole_map(building, monkeypatch) -> None:
    """Re-scoring sees only the modes kept so far: one that passes the decision there
    brings the next whole-map search forward, and is accepted only if it passes that."""
    from autonomy.localization.relocalization import GlobalLocalizer

    calls: list[tuple[str, bool]] = []
    for name in ("search", "rescore"):
        original = getattr(GlobalLocalizer, name)

        def wrapped(self, *args, _original=original, _name=name, **kwargs):
            res = _original(self, *args, **kwargs)
            if _name == "search" or len(args[0]) > 1:  # not the prior's own re-scoring
                calls.append((_name, res.accepted is not None))
            return res

        monkeypatch.setattr(GlobalLocalizer, name, wrapped)
    stack = make_stack(building, pose=None)
    truth, inc = START.copy(), None
    for k in range(200):
        stack.perceive(render(building[1], truth))
        stack.localize(inc, k / 10.0)
        if not stack.lost.relocalizing:
            break
        inc = stack.decide(k / 10.0).velocity / 10.0
        truth = compose_pose(truth, inc)
    assert not stack.lost.relocalizing and calls, calls
    assert calls[-1] == ("search", True), calls  # accepted on a whole-map search
    passed = [i for i, (name, ok) in enumerate(calls) if ok]
    assert len(passed) >= stack.cfg.recovery.relocalization.confirmations
    assert any(name == "rescore" for name, _ in calls[:-1]), calls  # a re-score passed first, then the search came


def test_an_unknown_start_after_a_blackout_still_looks_round(building) -> None:
    stack = make_stack(building)
    drive(stack, [None] * 30)
    assert stack.health_state == "blind"
    stack.reset(None)
    assert stack.decide(1.0).state == "looking"


def exploring_from(stack, a: np.ndarray, b: np.ndarray, monkeypatch) -> list[np.ndarray]:
    """Lost at START with modes ``a`` (best) and ``b`` (map-from-odometry transforms);
    returns the list that the poses given to the navigator are appended to."""
    stack.lost.view.modes = [(a, 0.1), (b, 0.11)]
    stack.state.odom = START.copy()
    seen: list[np.ndarray] = []
    real = stack.navigator.command

    def spy(pose, *args, **kwargs):
        seen.append(np.array(pose))
        return real(pose, *args, **kwargs)

    monkeypatch.setattr(stack.navigator, "command", spy)
    return seen


def test_an_exploring_drive_keeps_the_mode_it_set_out_on(building, monkeypatch) -> None:
    """Undecided after explore_after_s, the robot drives on the best mode. When the
    re-scored modes change their order mid-drive, the navigator goes on seeing the world
    through the transform the drive began with (its plan, memory and blind-spot walls
    were placed through it), until it looks round again."""
    stack = make_stack(building, pose=None)
    a = np.array([0.0, 0.0, 0.0])  # modes as map-from-odometry transforms
    b = np.array([12.0, -4.0, math.pi / 2])
    seen = exploring_from(stack, a, b, monkeypatch)
    t = stack.cfg.recovery.explore_after_s + 1.0
    assert stack.decide(t).state in ("exploring", "turning", "driving", "arrived")
    stack.lost.view.modes = [(b, 0.09), (a, 0.1)]  # re-scored: the other mode is best now
    stack.state.odom = compose_pose(START, np.array([0.2, 0.0, 0.05]))
    stack.decide(t + 0.1)
    np.testing.assert_allclose(seen[0], compose_pose(a, START))
    np.testing.assert_allclose(seen[-1], compose_pose(a, stack.state.odom))


def test_an_exploring_drive_on_a_mode_the_scan_rules_out_sets_out_again_on_the_best(building, monkeypatch) -> None:
    """Once the mode a drive set out on scores worse than the best by more than
    ``abandon_margin`` (or is no longer kept), the robot does not drive on through it
    until the drive times out: it sets out at once on the best mode, without a new look."""
    stack = make_stack(building, pose=None)
    a = np.array([0.0, 0.0, 0.0])  # modes as map-from-odometry transforms
    b = compose_pose(np.array([18.0, 6.3, math.pi]), relative_pose(START, np.zeros(3)))  # the south corridor
    seen = exploring_from(stack, a, b, monkeypatch)
    t = stack.cfg.recovery.explore_after_s + 1.0
    stack.decide(t)
    margin = stack.cfg.recovery.active.abandon_margin
    stack.lost.view.modes = [(b, 0.1), (a, 0.1 + 0.5 * margin)]  # within the margin: drive on
    stack.decide(t + 0.1)
    np.testing.assert_allclose(seen[-1], compose_pose(a, stack.state.odom))
    stack.lost.view.modes = [(b, 0.1), (a, 0.1 + 2.0 * margin)]  # ruled out
    cmd = stack.decide(t + 0.2)
    np.testing.assert_allclose(seen[-1], compose_pose(b, stack.state.odom))
    assert cmd.state != "looking"
    np.testing.assert_allclose(stack.lost.motion.explore_T, b)
    stack.lost.view.modes = [(b, 0.1)]  # a is no longer kept at all; b's drive goes on
    stack.decide(t + 0.3)
    np.testing.assert_allclose(seen[-1], compose_pose(b, stack.state.odom))


def test_an_exploring_drive_goes_where_the_modes_predict_different_walls(building) -> None:
    """Two modes 4 m apart in the long corridor south of the offices, both facing west,
    see the same two parallel walls. The drive chosen is the one, of all the robot could
    set out on, that tells them apart best on the map; the node most nearly ahead (the
    choice without active localization) would hardly tell them apart."""
    pose = np.array([18.0, 6.3, math.pi])
    other = np.array([22.0, 6.3, math.pi])
    stacks = []
    for enabled in (True, False):
        rec = StackConfig().recovery
        stack = make_stack(building, pose=None, recovery=replace(rec, active=replace(rec.active, enabled=enabled)))
        stack.state.odom = np.zeros(3)  # modes as map-from-odometry transforms: the poses
        stack.lost.view.modes = [(pose, 0.05), (other, 0.052)]
        stacks.append(stack)
    active, plain = stacks
    assert plain.lost.motion._compared_modes(pose).shape == (0, 3)
    modes = active.lost.motion._compared_modes(pose)
    assert len(modes) == 2
    nav = active.navigator

    def value(node: int) -> float:
        return active.lost.motion._drive_value(nav.plan_points(node, pose), modes)

    chosen, ahead = active.lost.motion.explore_node(pose, 0.0), plain.lost.motion.explore_node(pose, 0.0)
    xy = nav.graph.node_xy()
    d = np.hypot(xy[:, 0] - pose[0], xy[:, 1] - pose[1])
    values = [value(int(nav.graph.nodes[int(k)].id)) for k in np.flatnonzero((d >= 6.0) & (d <= 12.0))]
    assert value(chosen) == pytest.approx(max(values))
    assert value(ahead) < 0.5 * value(chosen)


def test_an_exploring_drive_does_not_set_out_into_walls_the_scan_has_seen(building) -> None:
    """The exploring drive's node is the one most nearly ahead whose plan (on the best
    mode's map) starts clear of the scan's points of the last SEEN_KEEP_S; a wrong mode's
    way out of a room can lead into a wall the robot has seen. With every way blocked,
    the one ahead is tried. A wall seen longer ago no longer counts: dead reckoning has
    moved it since."""
    from autonomy.common.geometry import points_in_frame
    from autonomy.stack import SEEN_KEEP_S

    stack = make_stack(building, pose=None)
    stack.state.odom = np.zeros(3)
    pose = START.copy()  # the best mode's belief
    ahead = stack.lost.motion.explore_node(pose, 0.0)
    assert ahead is not None
    path = points_in_frame(pose, stack.navigator.plan_points(ahead, pose))
    # A wall across that plan, 1.5 m along it, in the scan.
    seg_len = np.hypot(*np.diff(path, axis=0).T)
    k = int(np.searchsorted(np.cumsum(seg_len), 1.5))
    f = (1.5 - (np.cumsum(seg_len)[k] - seg_len[k])) / seg_len[k]
    at = path[k] + f * (path[k + 1] - path[k])
    u = (path[k + 1] - path[k]) / seg_len[k]
    wall = at + np.outer(np.linspace(-1.0, 1.0, 41), [-u[1], u[0]])
    stack.lost.view.scan.add(np.zeros(3), wall, 0.0)
    other = stack.lost.motion.explore_node(pose, 0.0)
    assert other is not None and other != ahead
    stack.lost.motion.explored.clear()
    assert stack.lost.motion.explore_node(pose, SEEN_KEEP_S + 0.1) == ahead
    stack.lost.motion.explored.clear()
    from autonomy.common.geometry import polyline_clear

    r = stack.cfg.avoidance.robot_radius_m
    assert polyline_clear(points_in_frame(pose, stack.navigator.plan_points(other, pose)), wall, stack.cfg.recovery.explore_check_m, r - 0.05)
    # Walled in all round: the node ahead after all.
    ring = 0.9 * np.column_stack([np.cos(np.linspace(0, 2 * np.pi, 200)), np.sin(np.linspace(0, 2 * np.pi, 200))])
    stack.lost.view.scan.add(np.zeros(3), ring, 0.0)
    assert stack.lost.motion.explore_node(pose, 0.0) == ahead


def test_prepare_recovery_builds_the_map_search_up_front(building) -> None:
    stack = make_stack(building)
    assert stack.lost._global is None
    stack.prepare_recovery()
    gl = stack.lost._global
    assert gl is not None and len(gl.candidates) > 1000
    stack.prepare_recovery()
    assert stack.lost._global is gl  # once
    off = make_stack(building, recovery=replace(stack.cfg.recovery, enabled=False))
    off.prepare_recovery()
    assert off.lost._global is None


def test_prepare_recovery_loads_the_kernels_the_search_uses() -> None:
    """In a fresh process, after prepare_recovery a map search (and the count of the
    scan's wall points) compiles or loads no kernel of its own: each of the search's kernels has the one signature the warm-up
    gave it (a warm-up with other argument types would leave the search to load its own
    at the first alarm, a step in a long run's memory)."""
    import subprocess
    import sys

    code = """
import numpy as np
from autonomy.localization.relocalization import _grid_costs, _refine, _through_counts
from autonomy.stack import RobotStack, StackConfig
from autonomy.localization.straight_runs import _straight_runs, on_straight_runs
from sim.simulator.blueprints import load_blueprint
bp = load_blueprint("corridor_loop")
stack = RobotStack(bp.vectormap, bp.navgraph, StackConfig(), rng=np.random.default_rng(0))
stack.prepare_recovery()
kernels = (_grid_costs, _refine, _through_counts, _straight_runs)
warm = [len(k.signatures) for k in kernels]
ring = np.column_stack([3.0 * np.cos(np.linspace(0, 6, 200)), 2.0 * np.sin(np.linspace(0, 6, 200))])
stack.lost._global.search(ring, origins=np.zeros_like(ring))
stack.lost.view.scan.add(stack.state.odom, ring, 0.0)
on_straight_runs(stack.lost.view.scan.points, 1.5)
print(warm, [len(k.signatures) for k in kernels])
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[1, 1, 1, 1] [1, 1, 1, 1]", out.stdout + out.stderr


#: In the atrium's west aisle, 4 m from its west wall: looking round, the camera (4 m
#: range) sees two pillars' faces, too few points to search the map.
HALL = np.array([25.3, 15.25, math.pi])


@pytest.mark.slow
def test_an_unknown_start_where_no_wall_is_in_range_drives_to_find_walls(building) -> None:
    """reset(None) in the atrium, perfect odometry, the camera seeing the map from the
    true pose (with 3 mm of noise: a view of bare floor repeats exactly as the robot
    turns, and the stack would drop it as stale). After the sweep the scan is too small
    to search and no mode exists; the robot drives on dead reckoning towards what it saw
    until walls come into range, looks round again, and relocalizes within 50 s. A robot
    that only looked round would turn in place for ever."""
    stack = make_stack(building, pose=None)
    rc = stack.cfg.recovery.relocalization
    noise = np.random.default_rng(5)
    fps = 10.0
    truth, inc, states, swept_small = HALL.copy(), None, [], None
    for k in range(int(50 * fps)):
        t = k / fps
        z = render(building[1], truth)
        stack.perceive(np.where(z > 0, z + noise.normal(0.0, 0.003, z.shape), 0.0).astype(np.float32))
        stack.localize(inc, t)
        if not stack.lost.relocalizing:
            break
        if swept_small is None and stack.lost.view.scan.turned_rad >= math.radians(rc.min_sweep_deg):
            swept_small = (len(stack.lost.view.scan.points), len(stack.lost.view.modes))
        cmd = stack.decide(t)
        states.append((cmd.state, len(stack.lost.view.modes)))
        inc = cmd.velocity / fps
        truth = compose_pose(truth, inc)
    assert swept_small is not None and swept_small[0] < rc.min_scan_points and swept_small[1] == 0, swept_small
    assert ("exploring", 0) in states, "it never drove without a mode"
    assert not stack.lost.relocalizing, (t, stack.lost.last_search.reason if stack.lost.last_search else None)
    err = relative_pose(truth, stack.state.pose)
    assert math.hypot(err[0], err[1]) < 0.15 and abs(wrap_angle(err[2])) < math.radians(3.0), err


def test_a_scan_of_pillars_and_furniture_alone_sends_the_robot_to_find_walls(building) -> None:
    """Looked round, a scan of 300 points, every one on a short face (0.5 m pillars in a
    row, chairs, a cabinet's 0.9 m side), holds no wall: the robot drives to find one
    (``min_wall_points``), the way open between the faces, rather than look on (a
    scan that only had to hold 150 points counted as enough). Once the scan holds a
    3 m wall, the drive ends; with ``min_wall_points`` = 0, only the size counts."""

    short = [points_along((x, y - 0.25), (x, y + 0.25)) for x in (1.5, 2.0) for y in np.arange(-3.0, 3.1, 1.0)]
    short += [points_along((x - 0.25, y), (x + 0.25, y)) for x in (-2.0, -1.2, -0.4) for y in (1.5, 2.0, -1.5, -2.0)]
    short += [points_along((-2.5, -0.45), (-2.5, 0.45))]
    clutter = np.vstack(short)
    assert len(clutter) >= 150
    for min_wall_points, want in ((40, "exploring"), (0, "looking")):
        stack = make_stack(building, pose=None)
        rc = stack.cfg.recovery.relocalization
        stack = make_stack(building, pose=None, recovery=replace(stack.cfg.recovery, relocalization=replace(rc, min_wall_points=min_wall_points)))
        stack.lost.view.scan.add(stack.state.odom, clutter, 1.0)
        stack.lost.view.scan.turned_rad = 2 * math.pi
        cmd = stack.decide(1.0)
        assert cmd.state in ((want, "turning") if want == "exploring" else (want,)), (min_wall_points, cmd.state)
        if want == "exploring":
            # The way out is open for the first 3 m (ahead, the pillars' row is 0.5 m
            # apart: too narrow; the mean of the points is ahead too).
            assert stack.lost.motion.probe is not None
            way = np.array([0.0, 0.0, 3.0 * math.cos(stack.lost.motion.probe[1]), 3.0 * math.sin(stack.lost.motion.probe[1])])
            assert point_segment_distance(clutter, way[None, :]).min() > stack.cfg.avoidance.robot_radius_m, math.degrees(stack.lost.motion.probe[1])
            stack.lost.view.scan.add(stack.state.odom, points_along((-1.5, 3.0), (1.5, 3.0)) + (0.0, 0.5), 1.6)
            stack.decide(1.6)
            assert stack.lost.motion.probe is None


def test_a_drive_to_find_walls_sets_out_the_way_most_open() -> None:
    """Seen all round 1.5 m off but for a 1.27 m gap on the left, the way out is through
    the gap (a way towards what the scan holds can end at a chair); with nothing seen,
    straight on; open equally to the left and right, the one nearer ahead."""
    a = np.radians(np.arange(0.0, 360.0, 2.0))
    ring = 1.5 * np.column_stack([np.cos(a), np.sin(a)])
    gap = np.abs(wrap_angles(a - math.pi / 2)) < math.radians(25.0)
    assert abs(most_open_way(ring[~gap], 0.3, 6.0) - math.pi / 2) <= math.radians(10.0)
    assert most_open_way(np.zeros((0, 2)), 0.3, 6.0) == 0.0
    # A wall 1 m ahead across the robot's way, and one 2 m behind: left and right tie,
    # and of those the nearest ahead is taken.
    ahead = np.column_stack([np.full(41, 1.0), np.linspace(-0.5, 0.5, 41)])
    behind = np.column_stack([np.full(41, -2.0), np.linspace(-0.5, 0.5, 41)])
    way = most_open_way(np.vstack([ahead, behind]), 0.3, 6.0)
    assert math.radians(49.0) <= abs(way) <= math.radians(90.0), math.degrees(way)


#: In the atrium, the robot's centre 0.57 m from a pillar's corner (a kidnapped run
#: looked round here, then set out into the pillar): nothing of the pillar is farther
#: from the camera than its 0.8 m minimum range while it faces the pillar.
BY_PILLAR = np.array([30.9631, 14.9466, 2.808])
PILLAR = np.array([30.535, 14.157])  # its centre; 0.5 m square


def _look_round_by_the_pillar(building) -> tuple[RobotStack, np.ndarray]:
    """A stack with an unknown start that has looked round once beside the pillar
    (perfect odometry: odom = truth - start); the true pose after it."""
    stack = make_stack(building, pose=None)
    noise = np.random.default_rng(2)
    truth, inc, fps = BY_PILLAR.copy(), None, 10.0
    for k in range(int(12 * fps)):
        z = render(building[1], truth)
        stack.perceive(np.where(z > 0, z + noise.normal(0.0, 0.003, z.shape), 0.0).astype(np.float32))
        stack.localize(inc, k / fps)
        inc = stack.navigator.look_around(k / fps).velocity / fps
        truth = compose_pose(truth, inc)
    return stack, truth


def test_kept_near_field_points_a_modes_map_explains_give_way_to_its_walls(building) -> None:
    """A drive planned on a mode leaves out the kept near-field points whose sight line a
    wall of that mode's map explains (the map's pillar counts there, where it stands);
    on a mode whose map has no wall there they stay, the robot's only knowledge of it."""
    stack, truth = _look_round_by_the_pillar(building)
    n_scan = len(stack.lost.view.scan.recent_in_robot_frame(stack.state.odom, 12.0 - 15.0))
    kept = len(stack.lost.view.seen_now(12.0)) - n_scan
    assert kept > 20
    # The true place: the pillar is mapped where the near field saw it (all but a few
    # sight lines past its edges, which it passes farther than near_wall_tol_m from).
    assert len(stack.lost.view.seen_now(12.0, truth)) - n_scan <= 0.15 * kept
    # A mode 3 m off along the corridor, with no wall within the near field's reach.
    wrong = truth + np.array([-3.0, 0.0, 0.0])
    assert stack.navigator.surroundings.map_points(wrong, 1.0, with_seen=False).shape[0] == 0
    assert len(stack.lost.view.seen_now(12.0, wrong)) - n_scan == kept


def test_what_the_near_field_shows_while_looking_round_keeps_a_drive_off_it(building) -> None:
    """Looking round beside the pillar, the scan holds nothing of it (it never lies within
    the camera's range), but the near field shows it whenever the camera faces it. Those
    points are kept (dead-reckoning frame) for SEEN_KEEP_S and count with the scan's in
    the camera's blind spots: a drive set out towards the pillar swerves off it, where the
    scan alone would let it drive straight on. Every point kept lies towards the pillar.
    After SEEN_KEEP_S, neither the near field's points nor the scan's count."""
    from autonomy.stack import SEEN_KEEP_S

    stack, truth = _look_round_by_the_pillar(building)
    to_pillar = PILLAR - truth[:2]
    scan = stack.lost.view.scan.in_robot_frame(stack.state.odom)
    assert not len(scan) or np.hypot(scan[:, 0], scan[:, 1]).min() > 1.0
    seen = stack.lost.view.seen_now(12.0)
    assert len(seen) > len(scan)
    near = seen[len(scan):]
    assert len(near) > 20
    bearing = np.arctan2(near[:, 1], near[:, 0]) + truth[2]
    off = np.abs(wrap_angles(bearing - math.atan2(to_pillar[1], to_pillar[0])))
    assert off.max() < math.radians(40.0), math.degrees(off.max())  # the pillar spans +-30 degrees from here
    # The pillar's direction in the dead-reckoning frame the drive steers in.
    heading = float(stack.state.odom[2]) + wrap_angle(math.atan2(to_pillar[1], to_pillar[0]) - float(truth[2]))
    # Turned in place to face it: the same points relative to the robot facing that way.
    o = stack.state.odom
    facing = np.array([o[0], o[1], heading])

    def turned(p: np.ndarray) -> np.ndarray:
        return points_in_frame(facing, points_from_frame(o, p))

    nav = stack.navigator
    nav.pose_jumped()
    free = nav.head_for(facing, heading, np.zeros((0, 2)), 12.0, seen=turned(scan))
    assert free.state == "driving" and free.theta_star_rad == pytest.approx(0.0)
    kept = nav.head_for(facing, heading, np.zeros((0, 2)), 12.0, seen=turned(seen))
    assert kept.state == "blocked" or abs(kept.theta_star_rad) > math.radians(20.0), kept
    late = 12.0 + SEEN_KEEP_S
    stack.lost.view.keep_near(None, late)
    assert len(stack.lost.view.seen_now(late)) == 0
