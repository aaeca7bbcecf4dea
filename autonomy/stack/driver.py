"""What drives the robot: the typed protocol for putting your own stack in the loop.

A scenario's robot is driven by this project's :class:`autonomy.stack.RobotStack` unless
its ``[driver]`` table names a factory (``factory = "my_robot.nav:make"``, or
``"driver.py:make"`` for a file beside the scenario). The factory is called once per run
with a :class:`DriverSetup` and returns a :class:`Driver`. The simulation then hands the
driver what a real robot's driver gets, and nothing else (no ground truth):

- :meth:`Driver.reset` once, with the start pose if the scenario says the robot knows it;
- :meth:`Driver.set_goal` at the start of each leg of the mission;
- :meth:`Driver.step` every Kinect frame (30 Hz): the depth image and the wheel odometry
  since the last frame in, a :class:`DriverCommand` out (the velocity until the next
  frame, and optionally the belief and "arrived").

The runner, faults, reports, figures, recordings, expectations and sweeps work for a
driver as for the project's stack. A driver that reports a belief gets the localization
figures (error against the truth, failures, resets); one that does not drives blind as
far as the report is concerned. ``examples/reactive_driver.py`` is a worked example.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from autonomy.maps.navgraph import NavGraph
from autonomy.maps.vectormap import VectorMap
from autonomy.perception.camera import DepthCamera


@dataclass(frozen=True)
class DriverSetup:
    """What a driver knows before the run: the map, the robot and its camera."""

    vectormap: VectorMap
    """The building's walls (map frame, metres)."""
    navgraph: NavGraph
    """The navigation graph the mission's waypoints are nodes of."""
    camera: DepthCamera
    """The depth camera: intrinsics, mount on the base, valid range."""
    robot_radius_m: float
    """The base's radius (a cylinder)."""
    max_speed_mps: float
    """The base's top speed; faster commands are clipped."""
    max_angular_rad_s: float
    """The base's top turn rate; faster commands are clipped."""
    frame_rate_hz: float
    """Frames per second: :meth:`Driver.step` is called this often."""
    seed: int
    """A seed for the driver's own random draws (the run's, so a seeded run replays)."""


@dataclass(frozen=True)
class DriverGoal:
    """Where the current leg of the mission goes."""

    node: int
    """The goal's navigation-graph node id."""
    xy: np.ndarray
    """Its position (map frame, metres)."""
    t: float
    """Time the leg starts (seconds of the run)."""


@dataclass(frozen=True)
class DriverFrame:
    """One frame of the robot's sensors."""

    t: float
    """Time of the frame (seconds of the run)."""
    depth: np.ndarray | None
    """Depth image (H, W) float32 metres along the optical axis, 0 where invalid; None
    when the frame was lost (a fault the scenario injects)."""
    odometry: np.ndarray | None
    """Wheel odometry since the last frame: (dx, dy, dtheta) in the base frame of the
    last frame (x forward, y left; metres, radians); None on the first frame."""


@dataclass(frozen=True)
class DriverCommand:
    """A driver's decision for the motion until the next frame."""

    velocity: np.ndarray
    """Base-frame velocity (vx, vy, omega): metres a second forward and left, radians a
    second counter-clockwise; the base is omnidirectional."""
    estimate: np.ndarray | None = None
    """The driver's belief of its pose (x, y, theta) in the map frame, if it has one:
    the run then measures its error against the truth."""
    arrived: bool = False
    """The driver believes it has reached the leg's goal (the run then checks it against
    the truth and starts the next leg)."""


@runtime_checkable
class Driver(Protocol):
    """A robot stack: frames and odometry in, velocity out (see the module docstring)."""

    def reset(self, start_pose: np.ndarray | None) -> None:
        """Start a run at ``start_pose`` (x, y, theta; map frame), or None when the robot
        does not know where it starts."""

    def set_goal(self, goal: DriverGoal) -> None:
        """Drive to ``goal`` next."""

    def step(self, frame: DriverFrame) -> DriverCommand:
        """Decide on one frame."""
