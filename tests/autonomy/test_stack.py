"""The robot stack behind one entry point, on a synthetic scene with a known answer.

The depth frame is rendered in closed form: a flat floor and a wall across the robot's
path at a known distance, seen by the default Kinect mount.
"""

from __future__ import annotations

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.common.geometry import compose_pose
from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
from autonomy.maps.vectormap import VectorMap
from autonomy.navigation.config import NavigatorConfig
from autonomy.perception.camera import DepthCamera
from autonomy.stack import LocalizationConfig, RobotStack, StackConfig
from tests.helpers import one_wall_depth

WALL_X = 2.5
CAM = DepthCamera()


def wall_depth(wall_x: float = WALL_X) -> np.ndarray:
    """Planar depth (float32 m, 0 beyond range) of the floor and a wall x = wall_x."""
    return one_wall_depth(CAM, wall_x)


def scene() -> tuple[VectorMap, NavGraph]:
    walls = np.array([[WALL_X, -5.0, WALL_X, 5.0], [-5.0, -5.0, WALL_X, -5.0], [-5.0, 5.0, WALL_X, 5.0]])
    nodes = (NavNode(id=0, x=0.0, y=0.0), NavNode(id=1, x=1.5, y=0.0))
    return VectorMap(walls), NavGraph(nodes=nodes, edges=(NavEdge(s0_id=0, s1_id=1),))


def make_stack(**cfg) -> RobotStack:
    vm, g = scene()
    stack = RobotStack(vm, g, StackConfig(**cfg), rng=np.random.default_rng(0), fspf_seed=7)
    stack.reset(np.zeros(3))
    return stack


def test_perception_finds_the_wall_where_it_is() -> None:
    stack = make_stack()
    per = stack.perceive(wall_depth())
    assert per.planes.planes > 5
    assert len(per.points_2d) > 50
    np.testing.assert_allclose(per.points_2d[:, 0], WALL_X, atol=0.03)
    # Obstacles: the wall's points inside the height band, the floor dropped.
    assert len(per.obstacles) > 50 and np.all(np.abs(per.obstacles[:, 0] - WALL_X) < 0.05)
    assert stack.frame == 1


def test_same_seed_same_perception_and_frames_take_successive_seeds() -> None:
    a, b = make_stack(), make_stack()
    depth = wall_depth()
    pa, pb = a.perceive(depth), b.perceive(depth)
    np.testing.assert_array_equal(pa.planes.points, pb.planes.points)
    again = b.perceive(depth)
    assert not np.array_equal(again.planes.points, pa.planes.points)  # the next frame's seed
    np.testing.assert_array_equal(make_stack().perceive(depth, seed=8).planes.points, again.planes.points)


def test_localization_holds_a_known_pose_when_standing_still() -> None:
    stack = make_stack()
    depth = wall_depth()
    for _ in range(10):
        out = stack.step(depth, np.zeros(3), 0.0)
    # The wall fixes x and the heading; standing still, nothing moves y.
    assert abs(out.estimate[0]) < 0.03 and abs(out.estimate[2]) < 0.02
    assert out.spread[0] > 0 and set(out.timings_s) == {"fspf", "obstacles", "localization", "navigation"}


def test_without_localization_the_estimate_is_dead_reckoning() -> None:
    stack = make_stack(localization=LocalizationConfig(enabled=False))
    assert stack.localizer is None
    rng = np.random.default_rng(3)
    want = np.zeros(3)
    depth = wall_depth()
    for _ in range(5):
        inc = rng.normal(0.0, 0.05, 3)
        want = compose_pose(want, inc)
        stack.perceive(depth)
        stack.localize(inc)
    np.testing.assert_array_equal(stack.state.pose, want)
    stack.localize(np.array([np.nan, 0.0, 0.0]))  # a broken odometry message is ignored
    np.testing.assert_array_equal(stack.state.pose, want)


def test_decides_towards_the_goal_and_stops_short_of_the_wall() -> None:
    stack = make_stack()
    stack.set_goal(1, 0.0)
    out = stack.step(wall_depth(), None, 0.0)
    assert out.command is not None and out.command.state == "driving"
    assert out.velocity[0] > 0.1
    # A goal past the wall's reach is still planned, but the wall 0.5 m ahead blocks:
    # taking the wall's face alone, the robot turns towards a lane round it.
    near = make_stack(navigator=NavigatorConfig(shadow_m=0.0))
    near.set_goal(1, 0.0)
    cmd = near.step(wall_depth(0.9), None, 0.0).command
    assert cmd is not None and cmd.velocity[0] < 0.3
    # With the memory's shadow behind the face, no lane within reach is clear: it drives
    # on towards the wall, no faster than it can stop within the open length.
    near = make_stack()
    near.set_goal(1, 0.0)
    cmd = near.step(wall_depth(0.9), None, 0.0).command
    avoid = near.cfg.avoidance
    assert cmd is not None and cmd.open_length_m < 1.0
    assert cmd.velocity[0] ** 2 / (2.0 * avoid.max_decel_mps2) <= cmd.open_length_m - avoid.stop_distance_m


def test_relocalize_puts_the_belief_at_the_given_pose() -> None:
    stack = make_stack()
    stack.relocalize(np.array([0.5, -0.2, 0.1]))
    np.testing.assert_array_equal(stack.state.pose, [0.5, -0.2, 0.1])
    assert stack.localizer is not None
    assert np.abs(stack.localizer.particles[:, 0].mean() - 0.5) < 0.2


def test_a_stack_without_navigator_refuses_to_decide() -> None:
    vm, g = scene()
    sensing = RobotStack(vm, None, StackConfig(navigate=False), rng=np.random.default_rng(0))
    out = sensing.step(wall_depth(), None, 0.0)
    assert out.command is None and np.array_equal(out.velocity, np.zeros(3))
    with pytest.raises(InputError, match="no navigator"):
        sensing.decide(0.0)
    with pytest.raises(InputError, match="navigation graph"):
        RobotStack(vm, None, StackConfig(), rng=np.random.default_rng(0))


def test_correspondences_associate_wall_points_with_the_wall() -> None:
    stack = make_stack()
    stack.perceive(wall_depth())
    lines, idx = stack.correspondences()
    assert len(lines) >= 1
    hit = idx[idx >= 0]
    assert len(hit) > 0.8 * len(idx)
    assert np.allclose(lines[np.unique(hit)][:, [0, 2]], WALL_X)


def test_a_malformed_odometry_increment_is_a_one_line_error() -> None:
    stack = make_stack()
    stack.perceive(wall_depth())
    with pytest.raises(InputError, match=r"odometry increment expected \(dx, dy, dtheta\), got shape \(2,\)"):
        stack.localize(np.zeros(2))
