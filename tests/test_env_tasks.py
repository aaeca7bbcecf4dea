"""The decision-level tasks (``DepthNavPointGoal-v0``, ``DepthNavLocal-v0``): a decision every six
camera frames with one sensing, observations of what the robot stack knows round the
robot, and a collision term counted once per contact and bounded."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sim  # noqa: F401  (registers the tasks)
from autonomy.common.errors import InputError
from sim.envs.config import EnvConfig
from sim.envs.depthnav import DepthNavEnv, make
from sim.envs.loop import Reading
from sim.envs.observation import plan_observation, ranges_observation, unit_goal_observation
from sim.envs.reward import PointGoalReward, RewardConfig
from sim.envs.task import Episode
from sim.envs.tasks import LOCALNAV, POINTNAV, TASKS, max_episode_steps
from sim.simulator.robot import OdometryConfig
from tests.helpers import GL

needs_gl = pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")


@needs_gl
@pytest.mark.parametrize("task", sorted(TASKS))
def test_every_registered_task_passes_check_env(task: str) -> None:
    env = gym.make(task)
    assert env.spec is not None and env.spec.max_episode_steps == (1000 if task == "DepthNav-v0" else max_episode_steps(task))
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


@needs_gl
def test_a_decision_is_six_frames_with_one_sensing() -> None:
    env = make(LOCALNAV, odometry=OdometryConfig(0.0, 0.0))
    obs, info = env.reset(seed=1)
    loop = env.unwrapped._loop
    assert set(obs) == {"goal", "odometry", "ranges", "plan", "velocity"}
    t0, rendered0, pose0 = float(loop.site.world.data.time), loop.sim.frames, info["pose"]
    obs, _, _, _, info = env.step(np.array([0.6, 0.0, 0.3], np.float32))
    assert float(loop.site.world.data.time) - t0 == pytest.approx(0.2)
    assert loop.sim.frames - rendered0 == 1  # one render for the six frames
    # Without odometry noise the step's increment is the true motion over all six frames.
    c, s = math.cos(pose0[2]), math.sin(pose0[2])
    d = info["pose"][:2] - pose0[:2]
    want = [c * d[0] + s * d[1], -s * d[0] + c * d[1], (info["pose"][2] - pose0[2] + math.pi) % (2 * math.pi) - math.pi]
    np.testing.assert_allclose(obs["odometry"], want, atol=1e-5)
    assert obs["velocity"][0] > 0.1  # the base moves forward, lagging the command
    assert env.unwrapped.metadata["render_fps"] == 5
    env.close()


@needs_gl
def test_ranges_tell_a_wall_too_near_to_see_from_nothing_in_range() -> None:
    """Facing the corridor's west wall 0.5 m off (the camera sees nothing closer than
    0.8 m, so the depth there is invalid), the ranges ahead show the wall; behind, down
    the corridor, nothing within 4 m."""
    env = make(POINTNAV, observe_depth=True)
    obs, _ = env.reset(seed=0, options={"start_pose": (0.5, 5.1, math.pi), "goal": (8.0, 5.1)})
    ahead = obs["ranges"][0, 35:37]  # the bins either side of the heading (bin 36 starts at 0 rad)
    np.testing.assert_allclose(ahead, 0.5 / 4.0, atol=0.03)
    behind = obs["ranges"][0, [0, 71]]
    assert (behind == 1.0).all()
    depth = obs["depth"][..., 0]
    assert (depth[depth.shape[0] // 3 : 2 * depth.shape[0] // 3] == 0).mean() > 0.9  # invalid: too near
    assert np.array_equal(obs["ranges"][0], obs["ranges"][2])  # the history starts filled with the first
    env.close()


def test_ranges_observation_is_the_brute_force_nearest_per_bin() -> None:
    rng = np.random.default_rng(3)
    pts = rng.uniform(-5, 5, (400, 2))
    got = ranges_observation(pts, 36, 4.0)
    want = np.ones(36)
    for x, y in pts:
        r = math.hypot(x, y)
        if r < 4.0:
            k = min(35, int((math.atan2(y, x) + math.pi) // (2 * math.pi / 36)))
            want[k] = min(want[k], r / 4.0)
    np.testing.assert_allclose(got, want, rtol=1e-6)
    assert (ranges_observation(np.zeros((0, 2)), 8, 4.0) == 1.0).all()


def test_unit_goal_and_plan_points_in_the_robot_frame() -> None:
    pose = np.array([1.0, 2.0, math.pi / 2])
    np.testing.assert_allclose(unit_goal_observation(pose, np.array([1.0, 7.0]), 10.0), [0.5, 1.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(unit_goal_observation(pose, np.array([-29.0, 2.0]), 10.0), [1.0, 0.0, 1.0], atol=1e-6)
    # Without a plan: the goal, repeated.
    p = plan_observation(None, pose, np.array([1.0, 4.0]), 3, 1.0, 4.0)
    np.testing.assert_allclose(p, [[0.5, 0.0]] * 3, atol=1e-6)


def test_a_plan_is_observed_ahead_of_the_estimate() -> None:
    from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
    from autonomy.navigation.navigator import Navigator

    g = NavGraph(nodes=(NavNode(0, 0.0, 0.0), NavNode(1, 3.0, 0.0), NavNode(2, 3.0, 3.0)), edges=(NavEdge(0, 1), NavEdge(1, 2)))
    nav = Navigator(g)
    nav.set_goal(2, np.array([0.0, 0.0, 0.0]))
    # At (0.5, 0) heading north: the plan's points 1, 2, 3 and 4 m on are (1.5, 0), (2.5, 0),
    # (3, 0.5), (3, 1.5); in the robot frame (x north, y west), over 4 m.
    got = plan_observation(nav.plan, np.array([0.5, 0.0, math.pi / 2]), np.array([3.0, 3.0]), 4, 1.0, 4.0)
    want = np.array([[0.0, -1.0], [0.0, -2.0], [0.5, -2.5], [1.5, -2.5]]) / 4.0
    np.testing.assert_allclose(got, want, atol=1e-6)


def _reading(onsets: tuple[int, ...]) -> Reading:
    z = np.zeros(3)
    return Reading(np.zeros((2, 2), np.float32), z, z, z, (0.0, 0.0), len(onsets), onsets, z, None, None)


def test_collisions_are_penalised_once_per_contact_and_bounded() -> None:
    cfg = RewardConfig.from_config(EnvConfig(**{k: v for k, v in TASKS[POINTNAV].items()}))
    assert cfg.collision_debounce_s == 2.0 and cfg.collision_penalties == 5
    ep = Episode(start=np.zeros(3), goal=np.array([5.0, 0.0]), goal_node=0, field=_Flat())
    reward = PointGoalReward(cfg)
    terms = []
    # Contacts starting on frames 1 and 4 of the first decision (0.1 s apart), then one
    # decision later (0.2 s on), then 3 s later: only the first and the last count.
    for onsets in [(1, 4), (2,), *[()] * 14, (1,)]:
        terms.append(reward.score(ep, _reading(onsets)).terms["collision"])
    assert ep.collisions == 4
    assert terms[0] == -1.0 and terms[1] == 0.0 and terms[-1] == -1.0 and sum(terms) == -2.0
    # At most collision_penalties an episode.
    for _ in range(40):
        reward.score(ep, _reading((1,)))
    assert ep.penalised == 5


class _Flat:
    """A geodesic field that is the straight-line distance (enough for the reward's test)."""

    goal = np.array([5.0, 0.0])

    def distance(self, xy: np.ndarray) -> tuple[float, None]:
        return float(np.hypot(*(np.asarray(xy) - self.goal))), None


def test_the_frame_level_task_keeps_its_per_contact_reward() -> None:
    cfg = RewardConfig.from_config(EnvConfig())
    ep = Episode(start=np.zeros(3), goal=np.array([5.0, 0.0]), goal_node=0, field=_Flat())
    reward = PointGoalReward(cfg)
    assert reward.score(ep, _reading((1,))).terms["collision"] == -10.0
    assert reward.score(ep, _reading((1,))).terms["collision"] == -10.0


@pytest.mark.parametrize(
    "kwargs, needle",
    [
        (dict(frames_per_step=0), "frames_per_step"),
        (dict(observe_ranges=-1), "observe_ranges"),
        (dict(history=0), "history"),
        (dict(collision_debounce_s=-1.0), "collision_debounce_s"),
        (dict(goal_format="spherical"), "goal_format"),
    ],
)
def test_bad_task_arguments_are_one_line_errors(kwargs: dict, needle: str) -> None:
    with pytest.raises(InputError, match=needle):
        DepthNavEnv(**kwargs)


def test_an_unknown_task_is_a_one_line_error() -> None:
    with pytest.raises(InputError, match="DepthNavLocal-v0"):
        make("DepthNav-v9")


def test_the_new_keys_are_in_the_docstring_table() -> None:
    doc = DepthNavEnv.__doc__
    assert doc is not None
    for key in ("ranges", "plan", "velocity"):
        assert f"| ``{key}`` |" in doc
    for task in TASKS:
        assert f"``{task}``" in doc


def test_a_scenario_s_time_limit_counts_decisions_on_a_decision_level_task() -> None:
    from sim.scenario import SCENARIOS_DIR

    frames = EnvConfig.from_scenario(SCENARIOS_DIR / "demo.toml")
    decisions = EnvConfig.from_scenario(SCENARIOS_DIR / "demo.toml", frames_per_step=6)
    assert decisions.max_steps == math.ceil(frames.max_steps / 6)
    with pytest.raises(InputError, match="frames_per_step"):
        EnvConfig.from_scenario(SCENARIOS_DIR / "demo.toml", frames_per_step=0)
    np.testing.assert_allclose(frames.action_scale, [0.75, 0.75, 1.5])


@needs_gl
def test_the_clearance_term_counts_how_far_inside_the_margin_the_nearest_wall_is() -> None:
    """Beside the corridor's west wall, the term is the weight times (1 - gap / margin),
    the gap from the robot's surface to the nearest thing the stack knows of; far from
    everything it is 0, and off by default."""
    env = make(POINTNAV, clearance_reward=-0.2, clearance_m=0.4)
    radius = env.unwrapped.config.robot.radius_m
    env.reset(seed=0, options={"start_pose": (0.5, 5.1, math.pi), "goal": (8.0, 5.1)})
    _, _, _, _, info = env.step(np.zeros(3, np.float32))
    known = env.unwrapped._reading.output.known
    gap = float(np.min(np.hypot(*known.T))) - radius
    assert 0 < gap < 0.4
    assert info["reward_terms"]["clearance"] == pytest.approx(-0.2 * (1 - gap / 0.4), rel=1e-9)
    env.close()
    env = make(POINTNAV)
    env.reset(seed=0, options={"start_pose": (0.5, 5.1, math.pi), "goal": (8.0, 5.1)})
    assert env.step(np.zeros(3, np.float32))[4]["reward_terms"]["clearance"] == 0.0
    env.close()


def test_a_clearance_term_needs_the_ranges() -> None:
    with pytest.raises(InputError, match="clearance_reward"):
        DepthNavEnv(clearance_reward=-0.1)


@needs_gl
def test_the_safety_layer_stops_a_robot_driven_at_a_wall() -> None:
    """Facing the corridor's west wall 0.5 m away, full speed ahead for 4 s touches it;
    through the safety layer the robot stops short of it and still turns."""
    start = {"start_pose": (1.2, 5.1, math.pi), "goal": (8.0, 5.1)}
    ahead = np.array([1.0, 0.0, 0.0], np.float32)
    env = make(POINTNAV)
    env.reset(seed=0, options=start)
    for _ in range(20):
        info = env.step(ahead)[4]
    assert info["collisions"] >= 1
    env.close()
    env = make(POINTNAV, safety_layer=True)
    env.reset(seed=0, options=start)
    for _ in range(20):
        info = env.step(ahead)[4]
    assert info["collisions"] == 0
    assert 0.05 < abs(info["pose"][0] - 1.2) < 1.0
    heading = info["pose"][2]
    info = env.step(np.array([0.0, 0.0, 1.0], np.float32))[4]
    assert abs(info["pose"][2] - heading) > 0.05
    env.close()


def test_a_safety_layer_needs_the_ranges() -> None:
    with pytest.raises(InputError, match="safety_layer"):
        DepthNavEnv(safety_layer=True)
