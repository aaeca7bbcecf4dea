"""A safety layer under a velocity command: brake before what the robot knows of.

A learned local planner on a real robot drives through the robot's own safety
controller: the command's direction is the planner's, its speed is capped so that the
robot can still stop short of every obstacle it knows of along that direction. This is
BV2012's safe speed (Section V: the largest speed from which the robot stops within the
open path length d at deceleration a) applied to a direction chosen by someone else, with
two additions for a command held for ``hold_s`` seconds before the next decision:

- the robot first travels ``v * hold_s`` at the commanded speed, then brakes, so v is the
  largest speed with ``v * hold_s + v^2 / (2 a) <= d - stop`` (the root of that quadratic);
- a command that also turns sweeps its body-frame direction through ``omega * hold_s``
  while it is held, so d is the shortest open length over that sweep.

The open lengths are Eq. 3-4's (:func:`autonomy.navigation.avoidance.open_path_lengths`),
round the robot's circle widened by the safety margin; turning in place never moves a
round robot's body, so the turn rate passes unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from autonomy.common.constants import KINECT_MAX_RANGE_M, ROBOT_RADIUS_M, SAFETY_MARGIN_M
from autonomy.common.errors import InputError
from autonomy.navigation.avoidance import open_path_lengths

__all__ = ["SafetyLayerConfig", "safe_command", "braking_speed"]

#: Directions sampled over a turning command's sweep (the command's own included).
SWEEP_SAMPLES = 5


@dataclass(frozen=True)
class SafetyLayerConfig:
    """How close the safety layer lets the robot come to what it knows of."""

    robot_radius_m: float = ROBOT_RADIUS_M
    safety_margin_m: float = SAFETY_MARGIN_M
    """Added to the radius for the corridor swept along the command (Eq. 3-4's r)."""
    max_decel_mps2: float = 1.0
    """a: the braking deceleration counted on (the base's acceleration limit)."""
    stop_distance_m: float = 0.05
    """Open length kept in reserve after braking."""
    max_range_m: float = KINECT_MAX_RANGE_M
    """Open lengths are capped here: nothing is known farther."""

    def __post_init__(self) -> None:
        for name in ("robot_radius_m", "max_decel_mps2", "max_range_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"safety.{name}: expected a positive number, got {v!r}")
        for name in ("safety_margin_m", "stop_distance_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InputError(f"safety.{name}: expected a number >= 0, got {v!r}")


def braking_speed(open_m: float, hold_s: float, decel: float, stop_m: float) -> float:
    """The largest v with ``v * hold_s + v^2 / (2 decel) <= open_m - stop_m`` (0 when none)."""
    room = open_m - stop_m
    if room <= 0.0:
        return 0.0
    return decel * (math.sqrt(hold_s * hold_s + 2.0 * room / decel) - hold_s)


def safe_command(command: np.ndarray, points2d: np.ndarray, hold_s: float, cfg: SafetyLayerConfig | None = None) -> np.ndarray:
    """``command`` (body-frame vx, vy in m/s, omega in rad/s) with its translation scaled
    down, direction kept, to the speed from which the robot stops short of ``points2d``
    ((n, 2) obstacles in the robot frame) when the command is held ``hold_s`` seconds."""
    cfg = SafetyLayerConfig() if cfg is None else cfg
    cmd = np.asarray(command, dtype=np.float64)
    if cmd.shape != (3,) or not np.isfinite(cmd).all():
        raise InputError(f"safe_command: expected a finite (vx, vy, omega), got {command!r}")
    if not (math.isfinite(hold_s) and hold_s >= 0):
        raise InputError(f"safe_command: hold_s must be a number >= 0, got {hold_s!r}")
    speed = math.hypot(cmd[0], cmd[1])
    if speed == 0.0:
        return cmd.copy()
    heading = math.atan2(cmd[1], cmd[0])
    sweep = np.linspace(heading, heading + cmd[2] * hold_s, SWEEP_SAMPLES)
    d = float(open_path_lengths(points2d, sweep, cfg.robot_radius_m + cfg.safety_margin_m, cfg.max_range_m).min())
    v = braking_speed(d, hold_s, cfg.max_decel_mps2, cfg.stop_distance_m)
    out = cmd.copy()
    if speed > v:
        out[:2] *= v / speed
    return out
