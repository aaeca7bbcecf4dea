"""The registered DepthNav tasks: each id and the :class:`sim.envs.config.EnvConfig` fields it fixes.

``DepthNav-v0`` is the frame-level point-goal task (a decision every camera frame, the
depth image, the goal). The decision-level tasks decide at 5 Hz (``frames_per_step`` 6:
the physics and the people keep the camera's 30 Hz between decisions, and the robot
senses once per decision), observe what the robot stack knows round the robot
(``ranges``: the map's walls through the estimate, the obstacle memory and the near
field, all round, the last three decisions), the base's velocity and the goal with
every term in [-1, 1], and are scored with a reward a learner can credit (below):

- ``DepthNavPointGoal-v0``, PointNav: the goal alone (the task of ``DepthNav-v0`` at the
  decision level; a name of its own, not ``DepthNav-v1``, because ``DepthNav-v0`` stays
  the frame-level benchmark rather than an out-of-date version of it);
- ``DepthNavLocal-v0``, local navigation: the goal and the next five points of the robot
  stack's plan on the navigation graph, 1 m apart from the estimate's place on it, as a
  global planner hands a route to a learned local planner on a real robot.

A change that alters a task's episodes or scores is a new version; the old id stays.
docs/env.md explains the choices.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

POINTNAV_V0 = "DepthNav-v0"
POINTNAV = "DepthNavPointGoal-v0"
LOCALNAV = "DepthNavLocal-v0"

DECISION_HZ = 5.0
"""The decision-level tasks' decision rate (30 Hz camera frames / 6)."""

DECISION_LEVEL: Mapping[str, Any] = MappingProxyType(
    dict(
        frames_per_step=6,
        # 200 decisions: 40 s, the frame-level task's 33 s and a little for turning.
        max_steps=200,
        depth_shape=(60, 80),
        observe_depth=False,
        observe_ranges=72,
        ranges_max_m=4.0,
        history=3,
        observe_velocity=True,
        goal_format="unit",
        goal_scale_m=10.0,
        # The reward: 1 a metre of geodesic progress (about 6.5 along a typical route),
        # 5 on arrival, -0.01 a decision (2 % of the best progress a decision, 0.15 m),
        # and -1 a collision, once per contact (none again within 2 s) and at most 5 an
        # episode, so a robot pinned on a wall cannot drown the rest.
        progress_reward_per_m=1.0,
        success_reward=5.0,
        time_reward=-0.01,
        collision_reward=-1.0,
        collision_debounce_s=2.0,
        collision_penalties=5,
        terminate_on_collision=False,
    )
)

TASKS: Mapping[str, Mapping[str, Any]] = MappingProxyType(
    {
        POINTNAV_V0: MappingProxyType({}),
        POINTNAV: DECISION_LEVEL,
        LOCALNAV: MappingProxyType({**DECISION_LEVEL, "observe_plan": 5, "plan_spacing_m": 1.0}),
    }
)
"""Each registered id's EnvConfig fields (the rest keep their defaults)."""


def max_episode_steps(task: str) -> int:
    """The id's ``max_episode_steps`` (its ``max_steps``)."""
    return int(TASKS[task].get("max_steps", 1000))
