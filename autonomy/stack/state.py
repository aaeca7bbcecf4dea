"""What the robot stack's parts share within a frame: the belief, dead reckoning, the
last perception and the event log."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from autonomy.localization.cgr import UpdateStats
from autonomy.perception.camera import CameraMount
from autonomy.perception.fspf import FSPFResult


@dataclass
class Perception:
    """What one depth frame told the robot (robot frame)."""

    planes: FSPFResult
    """FSPF's plane-filtered points P with normals R, and outliers O."""
    points_2d: np.ndarray
    """P down-projected to the floor (k, 2), floor-like normals dropped (the observation)."""
    normals_2d: np.ndarray
    """Their unit 2D normals (k, 2)."""
    obstacles: np.ndarray
    """P u O inside the avoidance's height band, down-projected (m, 2)."""
    near_lines: np.ndarray
    """Near-field sight lines (n, 4): something closer than the camera's minimum range."""


def empty_perception() -> Perception:
    """A perception with nothing in it (before the first usable frame)."""
    z2, z3 = np.zeros((0, 2)), np.zeros((0, 3))
    return Perception(FSPFResult(z3, z3, z3, np.zeros(0, np.int64)), z2, z2, z2, np.zeros((0, 4)))


@dataclass
class StackState:
    """The belief and the last frame, read and written by the stack's parts
    (:class:`autonomy.stack.robot.RobotStack` and its recovery)."""

    mount: CameraMount
    """The camera mount FSPF and the near field use (the mount check corrects it)."""
    pose: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """The pose estimate (x, y, theta), map frame."""
    spread: tuple[float, float] = (0.0, 0.0)
    """(position spread m, heading spread rad) of the belief."""
    odom: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """Dead reckoning from the odometry alone (the relocalization's scan frame)."""
    perception: Perception | None = None
    """The last usable frame's perception."""
    depth: np.ndarray | None = None
    """The last usable depth image."""
    fresh: bool = False
    """Whether this frame's perception is new (not a dropped or stale frame's)."""
    t: float = 0.0
    """The time of the last :meth:`RobotStack.localize` that was given one (s)."""
    events: list[dict] = field(default_factory=list)
    """What the recovery did: {"t", "event": lost | relocalized | blind | seeing | mount corrected, ...}."""


@dataclass
class LocalizationFrame:
    """What one frame's localization step found: read by the lost test and the output."""

    lines: np.ndarray | None = None
    """The scene lines CGR's update associated the points with (None: no update)."""
    stats: UpdateStats | None = None
    """CGR's update statistics (None: no update this frame)."""
    correction: tuple[float, float] | None = None
    """How far the update moved the belief beyond the odometry (x, y m)."""
    view_agree: float = math.nan
    """The view check's agreement of this frame with the last (NaN: not checked)."""
