"""Plans on a belief cut off from the goal: the robot's to recover from, not a user error.

A strip of floor 20 m x 4 m split by a wall at x = 4 with no door: a small room (two
graph nodes) west of it, a corridor (eight nodes) east of it, and no edge between the
two parts of the navigation graph. A belief in the room while the robot was started in
the corridor is wrong (or the robot was carried off); planning on it must not stop the
run. A goal that the start itself has no path to stays the user's mistake.
"""

from __future__ import annotations

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
from autonomy.maps.planner import NoPathError, parts
from autonomy.maps.vectormap import VectorMap
from autonomy.navigation.navigator import Navigator
from autonomy.stack import RobotStack, StackConfig
from tests.helpers import box_segments

ROOM = (0, 1)
"""Node ids of the room west of the wall."""
CORRIDOR = tuple(range(2, 10))
"""Node ids of the corridor east of it, at x = 5, 7, ..., 19."""
IN_ROOM = np.array([2.0, 2.0, 0.0])
"""A pose in the room facing east, at the wall."""
IN_CORRIDOR = np.array([9.5, 2.0, 0.0])


def strip() -> tuple[VectorMap, NavGraph]:
    walls = np.array(box_segments(0.0, 0.0, 20.0, 4.0) + [(4.0, 0.0, 4.0, 4.0)], dtype=np.float64)
    xy = [(1.0, 2.0), (3.0, 2.0)] + [(5.0 + 2.0 * i, 2.0) for i in range(len(CORRIDOR))]
    nodes = tuple(NavNode(id=i, x=x, y=y) for i, (x, y) in enumerate(xy))
    pairs = [ROOM, *zip(CORRIDOR[:-1], CORRIDOR[1:], strict=True)]
    return VectorMap.from_segments(walls, name="strip"), NavGraph(nodes=nodes, edges=tuple(NavEdge(s0_id=a, s1_id=b) for a, b in pairs))


def make_stack(pose: np.ndarray | None) -> RobotStack:
    vm, g = strip()
    stack = RobotStack(vm, g, StackConfig(), rng=np.random.default_rng(0), fspf_seed=1)
    stack.reset(pose)
    return stack


def make_navigator() -> Navigator:
    vm, g = strip()
    return Navigator(g, walls=np.asarray(vm.segments))


def test_an_exploring_drive_is_not_set_out_through_a_wall_to_a_part_the_mode_cannot_reach() -> None:
    """Lost, undecided after ``explore_after_s``, on a best mode in the room: every node
    ``explore_m`` to twice that away lies in the corridor, which the room's part of the
    graph does not reach. The robot looks round again; no plan is made, no error raised."""
    stack = make_stack(None)
    stack.state.odom = np.zeros(3)  # modes as map-from-odometry transforms: the poses
    stack.lost.view.modes = [(IN_ROOM.copy(), 0.1)]
    cmd = stack.decide(stack.cfg.recovery.explore_after_s + 1.0)
    assert cmd.state == "looking" and stack.lost.motion.exploring_from is None
    assert stack.lost.motion.explore_node(IN_ROOM, 0.0) is None


def test_an_exploring_drive_still_sets_out_where_the_mode_reaches() -> None:
    stack = make_stack(None)
    stack.state.odom = np.zeros(3)
    stack.lost.view.modes = [(IN_CORRIDOR.copy(), 0.1)]
    cmd = stack.decide(stack.cfg.recovery.explore_after_s + 1.0)
    assert cmd.state != "looking" and stack.lost.motion.exploring_from is not None
    assert stack.navigator.goal in CORRIDOR and all(n in CORRIDOR for n in stack.navigator.plan_nodes)


def test_a_goal_the_belief_is_cut_off_from_is_planned_from_a_node_that_reaches_it() -> None:
    """Started in the corridor, the belief now in the room: the next goal in the corridor
    is planned from the corridor's node nearest the belief, not refused."""
    stack = make_stack(IN_CORRIDOR)
    stack.state.pose = IN_ROOM.copy()
    plan = stack.set_goal(CORRIDOR[-1], 5.0)
    assert plan.nodes[0] == CORRIDOR[0] and plan.nodes[-1] == CORRIDOR[-1]
    assert plan.remaining_m == pytest.approx(3.0 + 14.0)


def test_a_goal_the_start_has_no_path_to_stays_the_users_mistake() -> None:
    stack = make_stack(IN_CORRIDOR)
    with pytest.raises(NoPathError, match=r"^no path from node 4 .*to node 0 in the navigation graph$") as exc:
        stack.set_goal(ROOM[0], 0.0)
    assert isinstance(exc.value, InputError)
    # ... even once the belief has wandered into the room.
    stack.state.pose = IN_ROOM.copy()
    with pytest.raises(NoPathError):
        stack.set_goal(ROOM[1], 1.0)


def test_with_an_unknown_start_the_first_goal_stands_for_the_start() -> None:
    """Relocalizing from an unknown start (the belief at the origin, in the room), the
    first goal's length is the best guess's, not an error; a later goal with no path from
    the first is the user's mistake."""
    stack = make_stack(None)
    assert stack.set_goal(CORRIDOR[2], 0.0).remaining_m > 0.0
    with pytest.raises(NoPathError):
        stack.set_goal(ROOM[0], 1.0)


def test_the_navigator_plans_from_the_goals_part_when_the_pose_is_cut_off_from_it() -> None:
    nav = make_navigator()
    nav.set_goal(CORRIDOR[-1], IN_ROOM)
    assert nav.plan_nodes == list(CORRIDOR)
    np.testing.assert_allclose(nav.plan_points(CORRIDOR[-1], IN_ROOM)[1], (5.0, 2.0))
    assert nav.nearest_reachable_node(IN_ROOM[:2]) in ROOM
    assert nav.nearest_reachable_node(IN_ROOM[:2], goal_id=CORRIDOR[-1]) == CORRIDOR[0]
    assert not nav.route.connected(ROOM[1], CORRIDOR[0]) and nav.route.connected(CORRIDOR[0], CORRIDOR[-1])
    # The corridor's nodes lie behind the wall: no place to choose to go from the room.
    np.testing.assert_array_equal(nav.reaches([ROOM[0], CORRIDOR[0]], IN_ROOM), [True, False])
    np.testing.assert_array_equal(nav.reaches([ROOM[0], CORRIDOR[0]], IN_CORRIDOR), [False, True])


def test_a_re_plan_on_a_belief_that_jumped_into_a_cut_off_part_does_not_fail() -> None:
    """Driving in the corridor, the belief jumps into the room: the re-plan from it
    starts in the corridor's part of the graph."""
    nav = make_navigator()
    nav.set_goal(CORRIDOR[-1], IN_CORRIDOR)
    nav.pose_jumped(IN_ROOM, 1.0)
    assert nav.goal == CORRIDOR[-1] and nav.plan_nodes == list(CORRIDOR)


def test_a_stuck_recovery_on_a_belief_in_a_cut_off_part_re_plans_and_backs_off() -> None:
    """A belief stuck in the room (no progress along the plan for ``stuck_time_s``):
    the recovery re-plans from the corridor's part and goes on, as anywhere else."""
    nav = make_navigator()
    nav.set_goal(CORRIDOR[-1], IN_CORRIDOR)
    none = np.zeros((0, 2))
    nav.command(IN_ROOM, none, 0.0)
    cmd = nav.command(IN_ROOM, none, nav.cfg.stuck_time_s + 0.5)
    assert nav.recoveries == 1 and cmd.state in ("recovering", "turning", "looking back")
    assert nav.plan_nodes == list(CORRIDOR)


def test_the_graphs_parts_follow_the_edges_the_plans_take() -> None:
    """Stairs join two parts only for a planner that takes them (``exclude_stairs``)."""
    nodes = tuple(NavNode(id=i, x=float(i), y=0.0) for i in range(4))
    g = NavGraph(nodes=nodes, edges=(NavEdge(s0_id=0, s1_id=1), NavEdge(s0_id=1, s1_id=2, has_stairs=True)))
    wheeled, legged = parts(g), parts(g, exclude_stairs=False)
    assert wheeled[0] == wheeled[1] and len({*wheeled[1:]}) == 3
    assert legged[0] == legged[1] == legged[2] != legged[3]
