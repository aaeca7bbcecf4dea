"""One simulator step: the robot's command, people, physics, the Kinect frame, odometry.

Every user of the closed loop (the scenario runner, the drive recorder, the gymnasium env)
advances the simulated site through :class:`SimStep`, and draws its random streams from one
seed through :class:`EpisodeSeeds`, so the same seed gives the same run in all of them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from sim.simulator.kinect import KinectCamera
from sim.simulator.robot import Odometry
from sim.simulator.world import World

#: Kinect noise seeds stay below this (the noise kernels' seed range).
NOISE_SEED_MODULUS = 2**31


@dataclass(frozen=True)
class EpisodeSeeds:
    """The independent random streams of one run or episode, spawned from one seed."""

    actors: np.random.Generator
    """Random furniture and people."""
    mission: np.random.Generator
    """Waypoints, or the episode's start and goal."""
    odometry: np.random.Generator
    """Odometry noise."""
    localization: np.random.Generator
    """CGR's sampling (the robot stack)."""
    noise_seed: int
    """Base of the per-frame Kinect noise seeds (frame k uses ``noise_seed + k``)."""
    fspf_seed: int
    """Base of the per-frame FSPF seeds (the robot stack)."""

    @classmethod
    def from_seed(cls, seed: int) -> EpisodeSeeds:
        ss = np.random.SeedSequence(int(seed))
        actors, mission, odometry, noise = (np.random.default_rng(s) for s in ss.spawn(4))
        noise_seed, fspf_seed = (int(v) for v in noise.integers(0, 2**31, size=2))
        return cls(actors, mission, odometry, np.random.default_rng(ss.spawn(1)[0]), noise_seed, fspf_seed)


@dataclass
class SimFrame:
    """What the simulated robot's sensors give after a step (and the truth beside it)."""

    t: float
    """Simulated time of the frame (s)."""
    depth: np.ndarray | None
    """The Kinect frame: float32 planar depth in metres, 0 = invalid (a new array every
    frame); None where a fault dropped the frame (:mod:`sim.simulator.faults`; a step
    always captures one)."""
    increment: np.ndarray | None
    """Noisy odometry increment (dx, dy, dtheta) since the previous frame, robot frame;
    None for the first frame."""
    pose: np.ndarray
    """True pose (x, y, theta): for metrics, never for the robot."""
    new_contacts: int
    """Contact episodes that started during the step (0 or 1)."""
    timings_s: dict[str, float]
    """Seconds in physics (people and physics), render and noise."""


class SimStep:
    """Advances a world by one camera frame: command -> people -> physics -> capture -> odometry."""

    def __init__(self, world: World, camera: KinectCamera, odometry: Odometry, noise_seed: int) -> None:
        self.world = world
        self.camera = camera
        self.odometry = odometry
        self.noise_seed = int(noise_seed)
        self.frame_dt = 1.0 / camera.cfg.rate_hz
        self.n_substeps = max(1, round(self.frame_dt / float(world.model.opt.timestep)))
        self.frames = 0

    def _capture(self) -> tuple[np.ndarray, float, float]:
        seed = (self.noise_seed + self.frames) % NOISE_SEED_MODULUS
        self.frames += 1
        depth = self.camera.capture(self.world.data, seed)
        return depth, self.camera.last_render_s, self.camera.last_noise_s

    def first(self) -> SimFrame:
        """The frame at the current state (after a reset), so the robot sees before it moves."""
        depth, r, n = self._capture()
        pose = self.world.robot.pose(self.world.data)
        return SimFrame(float(self.world.data.time), depth, None, pose, 0, {"physics": 0.0, "render": r, "noise": n})

    def step(self, velocity: np.ndarray, capture: bool = True) -> SimFrame:
        """Command the base (body frame vx, vy, omega), move the people, advance the
        physics one frame, capture the next Kinect frame and read the odometry.
        ``capture`` False: no frame is rendered (``depth`` None), for a robot that senses
        at a lower rate than the camera's (the noise seeds count captured frames only)."""
        w = self.world
        t0 = time.perf_counter()
        t = float(w.data.time)
        pose = w.robot.pose(w.data)
        w.robot.command(w.data, velocity, self.frame_dt)
        w.people.update(w.data, t + self.frame_dt, pose[:2])
        contacts = w.step_frame(self.n_substeps)
        physics = time.perf_counter() - t0
        depth, r, n = self._capture() if capture else (None, 0.0, 0.0)
        new_pose = w.robot.pose(w.data)
        inc = self.odometry.update(new_pose)
        return SimFrame(float(w.data.time), depth, inc, new_pose, contacts, {"physics": physics, "render": r, "noise": n})
