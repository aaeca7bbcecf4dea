"""One episode's closed loop in ``DepthNav-v0``: the simulator step and the robot stack.

The env advances its site through the same :class:`sim.simulator.step.SimStep` and
:class:`autonomy.stack.RobotStack` a scenario run uses. :class:`EpisodeLoop` does one
frame of that and returns a :class:`Reading`, everything of the frame that the
observation, the reward, the info and the rendering read.
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass, replace

import numpy as np

from autonomy.common.geometry import compose_pose
from autonomy.stack import RobotStack, StackConfig, StackOutput
from sim.envs.config import EnvConfig
from sim.envs.site import Site
from sim.envs.task import Episode
from sim.simulator.kinect import KinectConfig
from sim.simulator.robot import Odometry, OdometryConfig
from sim.simulator.step import EpisodeSeeds, SimFrame, SimStep

#: Depth beyond the GL far plane cannot occur (sim.simulator.world sets it at 60 m).
FAR_PLANE_M = 60.0

#: True in a process forked from one that had already opened an EGL display itself
#: (``kinect.render_process=False``): Mesa's renderer threads do not survive fork(), and
#: rendering there would hang for ever. The default render server is not affected.
_GL_INHERITED = False


def _after_fork_in_child() -> None:
    global _GL_INHERITED
    egl = sys.modules.get("mujoco.egl")
    if egl is not None and getattr(egl, "EGL_DISPLAY", None) is not None:
        _GL_INHERITED = True


os.register_at_fork(after_in_child=_after_fork_in_child)


@dataclass(frozen=True)
class LoopConfig:
    """The simulator's and the robot stack's settings, with the camera at the observation's size."""

    kinect: KinectConfig
    """The camera with intrinsics scaled to ``depth_shape`` and its noise on one thread
    (the output does not depend on the thread count)."""
    stack: StackConfig
    """The robot stack for that camera (FSPF's ``eta_px`` scaled to it)."""
    odometry: OdometryConfig
    depth_max_m: float
    """The depth range: the noise model's maximum, or the far plane without one."""
    run_stack: bool
    """Whether the stack runs at all: for localization, FSPF points or its navigator."""
    stack_policy: bool
    """Whether the stack's navigator drives to the goal (its command goes in the info)."""
    navigate: bool
    """Whether the stack plans to the goal (for ``stack_policy``, ``ranges`` or ``plan``)."""
    frames_per_step: int
    """Camera frames per step; the robot senses on the last."""
    known_m: float
    """Radius of what the stack knows round the robot, read every frame for ``ranges`` (0: not read)."""
    reset_error_m: float
    """A belief this far from the truth is re-initialised there."""

    @classmethod
    def from_config(cls, cfg: EnvConfig) -> LoopConfig:
        h, w = cfg.depth_shape
        kinect = replace(cfg.kinect, intrinsics=cfg.kinect.intrinsics.scaled(w, h), noise=replace(cfg.kinect.noise, threads=1))
        fspf = replace(cfg.fspf, eta_px=max(2, round(cfg.fspf.eta_px * w / cfg.kinect.intrinsics.width)))
        max_range = cfg.kinect.noise.max_range_m
        return cls(
            kinect=kinect,
            stack=cfg.stack_config(kinect, fspf),
            odometry=cfg.odometry,
            depth_max_m=float(max_range) if math.isfinite(max_range) else FAR_PLANE_M,
            run_stack=cfg.localization.enabled or cfg.observe_points > 0 or cfg.stack_policy or cfg.observe_ranges > 0 or cfg.observe_plan > 0,
            stack_policy=cfg.stack_policy,
            navigate=cfg.stack_policy or cfg.observe_ranges > 0 or cfg.observe_plan > 0,
            frames_per_step=cfg.frames_per_step,
            known_m=cfg.ranges_max_m if cfg.observe_ranges > 0 else 0.0,
            reset_error_m=cfg.localization.reset_error_m,
        )


@dataclass(frozen=True, eq=False)
class Reading:
    """One frame as the env reads it: the sensors, the truth, and the stack's output."""

    depth: np.ndarray
    """Planar depth in metres, 0 = invalid (a new array every frame; observations copy it)."""
    increment: np.ndarray
    """Noisy odometry increment since the previous step (zeros on the first frame)."""
    pose: np.ndarray
    """True pose (x, y, theta)."""
    estimate: np.ndarray
    """The pose estimate: CGR's, or dead reckoning without the stack."""
    spread: tuple[float, float]
    """The estimate's position and heading spread (zeros for dead reckoning)."""
    new_contacts: int
    """Contact episodes that started during the step."""
    contact_frames: tuple[int, ...]
    """The step's frames (1 = its first) on which each of them started."""
    velocity: np.ndarray
    """The base's body-frame velocity after the step (vx, vy, omega; the acceleration
    limits make it lag the command), as its wheel encoders measure it."""
    output: StackOutput | None
    """The stack's output on this frame (None without a stack)."""
    command: np.ndarray | None
    """The stack navigator's velocity command (with ``stack_policy``)."""


class EpisodeLoop:
    """One episode's simulator step and robot stack: advances a frame and reads it."""

    def __init__(self, config: LoopConfig, site: Site, seeds: EpisodeSeeds, episode: Episode) -> None:
        self.config = config
        self.site = site
        self.episode = episode
        """The episode the stack's localization resets are counted in."""
        start = episode.start
        self.sim = SimStep(site.world, site.camera, Odometry(config.odometry, seeds.odometry, start), seeds.noise_seed)
        self._stack: RobotStack | None = None
        if config.run_stack:
            b = site.building
            self._stack = RobotStack(b.vectormap, b.navgraph, config.stack, rng=seeds.localization, fspf_seed=seeds.fspf_seed, scene=site.query)
            self._stack.reset(start)
            if config.navigate:
                self._stack.set_goal(episode.goal_node, float(site.world.data.time), start)

    def first(self) -> Reading:
        """The frame at the start pose, seen before the robot moves."""
        return self._read(self._capture(None), np.zeros(3), ())

    def step(self, velocity: np.ndarray) -> Reading:
        """Command the base (body frame vx, vy, omega in m/s and rad/s) for
        ``frames_per_step`` frames; the robot senses on the last one, with the odometry of
        them all composed."""
        increment = np.zeros(3)
        onsets: list[int] = []
        for k in range(1, self.config.frames_per_step):
            frame = self.sim.step(velocity, capture=False)
            increment = compose_pose(increment, frame.increment)
            onsets += [k] * frame.new_contacts
        frame = self._capture(velocity)
        onsets += [self.config.frames_per_step] * frame.new_contacts
        increment = compose_pose(increment, frame.increment)
        return self._read(frame, increment, tuple(onsets))

    def _capture(self, velocity: np.ndarray | None) -> SimFrame:
        kin = self.config.kinect
        if _GL_INHERITED and self.site.camera._backend is None and kin.backend != "raycast" and not kin.render_process:
            raise RuntimeError(
                "DepthNav: this process was forked from one that had already rendered with EGL, "
                "and OpenGL cannot render after fork(); make AsyncVectorEnv(..., context='spawn') "
                "(or 'forkserver'), or create the vector env before rendering in the parent"
            )
        return self.sim.first() if velocity is None else self.sim.step(velocity)

    def _read(self, frame: SimFrame, increment: np.ndarray, onsets: tuple[int, ...]) -> Reading:
        """The robot stack on the new frame: FSPF, localization (or dead reckoning) on the
        step's odometry ``increment``, and when it navigates the navigator's decision
        (its command is used with ``stack_policy`` only)."""
        depth = frame.depth
        assert depth is not None  # the env injects no faults: every step captures a frame
        if not math.isfinite(self.config.kinect.noise.max_range_m):
            depth = np.where(depth <= self.config.depth_max_m, depth, np.float32(0.0))
        w = self.site.world
        velocity = w.robot.velocity_body(w.data)
        stack = self._stack
        if stack is None:
            estimate = self.sim.odometry.pose.copy()
            return Reading(depth, increment, frame.pose, estimate, (0.0, 0.0), len(onsets), onsets, velocity, None, None)
        odo = None if frame.increment is None else increment
        out = stack.step(
            depth, odo, frame.t, operator=lambda sensed: self._reset_far_belief(sensed, frame.pose), known_m=self.config.known_m
        )
        command = out.velocity.copy() if self.config.stack_policy else None
        return Reading(depth, increment, frame.pose, out.estimate, out.spread, len(onsets), onsets, velocity, out, command)



    def _reset_far_belief(self, sensed: StackOutput, truth: np.ndarray) -> np.ndarray | None:
        """The episode's localization reset, between the stack's localizing and deciding:
        a belief farther than ``reset_error_m`` from the ``truth`` is re-initialised there
        (counted in the episode's ``loc_resets``)."""
        if not sensed.localizing or math.hypot(*(sensed.estimate[:2] - truth[:2])) <= self.config.reset_error_m:
            return None
        self.episode.loc_resets += 1
        return truth
