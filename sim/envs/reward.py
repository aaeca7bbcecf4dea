"""The reward and the episode end of ``DepthNav-v0``.

:class:`PointGoalReward` scores each step from the episode's state and the new frame:
the reward terms (summed in ``REWARD_TERMS`` order), the episode's counters, and whether
the episode terminates or is truncated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from sim.envs.config import EnvConfig
from sim.envs.loop import Reading
from sim.envs.task import Episode

REWARD_TERMS = ("progress", "success", "collision", "time", "clearance")


@dataclass(frozen=True)
class RewardConfig:
    """The reward terms' weights and when an episode ends (the same fields of EnvConfig)."""

    progress_reward_per_m: float
    success_reward: float
    collision_reward: float
    collision_debounce_s: float
    collision_penalties: int
    time_reward: float
    clearance_reward: float
    clearance_m: float
    goal_radius_m: float
    terminate_on_success: bool
    terminate_on_collision: bool
    max_steps: int
    frames_per_step: int
    frame_s: float
    """Seconds per camera frame."""
    robot_radius_m: float
    """The base's radius (clearance counts from its surface)."""

    @classmethod
    def from_config(cls, cfg: EnvConfig) -> RewardConfig:
        names = [f.name for f in fields(cls) if f.name not in ("frame_s", "robot_radius_m")]
        return cls(**{n: getattr(cfg, n) for n in names}, frame_s=1.0 / cfg.kinect.rate_hz, robot_radius_m=cfg.robot.radius_m)


@dataclass(frozen=True)
class StepScore:
    """A step's reward, its terms, and whether the episode ended."""

    reward: float
    terms: dict[str, float]
    terminated: bool
    truncated: bool


class PointGoalReward:
    """Scores the steps of an episode and keeps its counters (steps, collisions, success,
    the last geodesic distance)."""

    def __init__(self, config: RewardConfig) -> None:
        self.config = config

    def begin(self, episode: Episode, reading: Reading) -> None:
        """Note the geodesic distance at the start, the first progress term's reference."""
        episode.phi, _ = episode.field.distance(reading.pose[:2])

    def _intrusion(self, reading: Reading) -> float:
        """How far inside ``clearance_m`` of the robot's surface the nearest point the
        stack knows of is, as a fraction (0: none within it, 1: at the surface)."""
        out = reading.output
        known = None if out is None else out.known
        if known is None or len(known) == 0:
            return 0.0
        gap = float(np.sqrt(np.min(np.einsum("ij,ij->i", known, known)))) - self.config.robot_radius_m
        return min(max(1.0 - gap / self.config.clearance_m, 0.0), 1.0)

    def score(self, episode: Episode, reading: Reading) -> StepScore:
        """Count the step into ``episode`` and score it on the true pose."""
        c = self.config
        ep = episode
        t0 = ep.steps * c.frames_per_step * c.frame_s
        ep.steps += 1
        ep.collisions += reading.new_contacts
        penalised = 0
        for k in reading.contact_frames:
            t = t0 + k * c.frame_s
            if c.collision_penalties and ep.penalised >= c.collision_penalties:
                break
            if t - ep.penalised_t < c.collision_debounce_s:
                continue
            penalised += 1
            ep.penalised += 1
            ep.penalised_t = t
        ep.collided = reading.new_contacts > 0
        pose = reading.pose
        phi, _ = ep.field.distance(pose[:2])
        reached = math.hypot(*(pose[:2] - ep.goal)) <= c.goal_radius_m
        first_success = reached and not ep.success
        ep.success = ep.success or reached
        terms = {
            "progress": c.progress_reward_per_m * (ep.phi - phi),
            "success": c.success_reward if first_success else 0.0,
            "collision": c.collision_reward * penalised,
            "time": c.time_reward,
            "clearance": c.clearance_reward * self._intrusion(reading) if c.clearance_reward else 0.0,
        }
        ep.phi = phi
        reward = float(sum(terms[k] for k in REWARD_TERMS))
        terminated = bool((c.terminate_on_success and reached) or (c.terminate_on_collision and reading.new_contacts > 0))
        truncated = bool(ep.steps >= c.max_steps and not terminated)
        return StepScore(reward, terms, terminated, truncated)
