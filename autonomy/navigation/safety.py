"""A safety layer under a velocity command: the safe velocity nearest to the command.

A learned local planner on a real robot drives through the robot's own safety
controller, which lets a command through when the robot can still stop short of every
obstacle it knows of, and otherwise changes it as little as it can (a minimal-intervention
safety filter). The speed the robot may have along a direction is BV2012's safe speed
(Section V: the largest speed from which it stops within the open path length d at
deceleration a), with two additions for a command held for ``hold_s`` seconds before the
next decision:

- the robot first travels ``v * hold_s`` at the commanded speed, then brakes, so v is the
  largest speed with ``v * hold_s + v^2 / (2 a) <= d - stop`` (the root of that quadratic);
- a command that also turns sweeps its body-frame direction through ``omega * hold_s``
  while it is held, so d is the shortest open length over that sweep.

The filtered command is the velocity nearest to the commanded one (vx, vy) among the
directions of a fan all round plus the command's own, each up to its safe speed: a
command that is safe passes unchanged, one towards a wall at an angle slides along it
instead of stopping dead (a policy that keeps asking for the same blocked direction
would otherwise stand there for good), one straight at a wall slows to its safe speed.
The open lengths are Eq. 3-4's (:func:`autonomy.navigation.avoidance.open_path_lengths`),
round the robot's circle widened by the safety margin; the radius, margin, deceleration,
stop distance and range are the robot's obstacle avoidance's (:class:`AvoidanceConfig`).
Turning in place never moves a round robot's body, so the turn rate passes unchanged.
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.errors import InputError
from autonomy.navigation.avoidance import AvoidanceConfig, open_path_lengths

__all__ = ["safe_command", "safe_speeds", "braking_speed"]

#: Directions sampled over a turning command's sweep (the command's own included).
SWEEP_SAMPLES = 5
#: Directions of the fan the filtered translation is chosen from (5 degrees apart).
FAN_DIRECTIONS = 72


def braking_speed(open_m, hold_s: float, decel: float, stop_m: float):
    """The largest v with ``v * hold_s + v^2 / (2 decel) <= open_m - stop_m`` (0 when
    none); a float for a float, an array for an array of open lengths."""
    room = np.maximum(np.asarray(open_m, dtype=np.float64) - stop_m, 0.0)
    v = decel * (np.sqrt(hold_s * hold_s + 2.0 * room / decel) - hold_s)
    return float(v) if v.ndim == 0 else v


def safe_command(command: np.ndarray, points2d: np.ndarray, hold_s: float, cfg: AvoidanceConfig | None = None) -> np.ndarray:
    """``command`` (body-frame vx, vy in m/s, omega in rad/s) with its translation
    replaced by the nearest one from which the robot stops short of ``points2d`` ((n, 2)
    obstacles in the robot frame) when the command is held ``hold_s`` seconds: along one
    of :data:`FAN_DIRECTIONS` directions all round or the command's own, at most that
    direction's safe speed (module docstring). The turn rate is kept."""
    cfg = AvoidanceConfig() if cfg is None else cfg
    cmd = np.asarray(command, dtype=np.float64)
    if cmd.shape != (3,) or not np.isfinite(cmd).all():
        raise InputError(f"safe_command: expected a finite (vx, vy, omega), got {command!r}")
    if not (math.isfinite(hold_s) and hold_s >= 0):
        raise InputError(f"safe_command: hold_s must be a number >= 0, got {hold_s!r}")
    speed = math.hypot(cmd[0], cmd[1])
    if speed == 0.0:
        return cmd.copy()
    heading = math.atan2(cmd[1], cmd[0])
    directions = np.concatenate([[heading], heading + np.arange(1, FAN_DIRECTIONS) * (2.0 * math.pi / FAN_DIRECTIONS)])
    limits = safe_speeds(directions, cmd[2], points2d, hold_s, cfg)
    if limits[0] >= speed:
        return cmd.copy()
    # Along direction e the nearest velocity to u is s e with s = u . e clipped to [0, limit].
    along = speed * np.cos(directions - heading)
    s = np.clip(along, 0.0, limits)
    k = int(np.argmin(s * s - 2.0 * s * along))  # |u - s e|^2 minus the constant |u|^2
    out = cmd.copy()
    out[0] = s[k] * math.cos(directions[k])
    out[1] = s[k] * math.sin(directions[k])
    return out


def safe_speeds(directions: np.ndarray, omega: float, points2d: np.ndarray, hold_s: float, cfg: AvoidanceConfig) -> np.ndarray:
    """The safe speed along each body-frame direction for a command turning at ``omega``
    held ``hold_s`` seconds: the braking speed of the shortest open length over the
    directions it sweeps through (:data:`SWEEP_SAMPLES` of them)."""
    dirs = np.asarray(directions, dtype=np.float64).reshape(-1)
    sweep = dirs[:, None] + np.linspace(0.0, omega * hold_s, SWEEP_SAMPLES)[None, :]
    d = open_path_lengths(points2d, sweep.ravel(), cfg.radius_m, cfg.max_range_m).reshape(sweep.shape).min(axis=1)
    return braking_speed(d, hold_s, cfg.max_decel_mps2, cfg.stop_distance_m)
