"""The carrot follower that drives Experiment III's robot round the corridor loop (on the
true pose: the robot drives, the maps use odometry)."""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import wrap_angle


class LoopDriver:
    """Carrot follower along the closed corridor path (ground truth: the robot drives, the map uses odometry)."""

    def __init__(self, path: np.ndarray, laps: float, speed: float, lookahead: float = 0.6) -> None:
        seg = np.diff(path, axis=0)
        self.lengths = np.hypot(seg[:, 0], seg[:, 1])
        self.lap_m = float(self.lengths.sum())
        self.path = path
        self.cum = np.concatenate([[0.0], np.cumsum(self.lengths)])
        self.goal_m = laps * self.lap_m
        self.speed = speed
        self.lookahead = lookahead
        self.s = 0.0

    def point(self, s: float) -> tuple[np.ndarray, float]:
        s = s % self.lap_m
        k = min(int(np.searchsorted(self.cum, s, side="right")) - 1, len(self.lengths) - 1)
        d = (self.path[k + 1] - self.path[k]) / self.lengths[k]
        return self.path[k] + d * (s - self.cum[k]), math.atan2(d[1], d[0])

    def command(self, pose: np.ndarray) -> np.ndarray | None:
        """Body velocity (vx, vy, w), or None when the distance is driven."""
        # Progress: the nearest path point within a window ahead of the last one.
        cand = self.s + np.linspace(-0.2, 1.0, 61)
        pts = np.array([self.point(c)[0] for c in cand])
        self.s = max(self.s, float(cand[int(np.argmin(np.hypot(*(pts - pose[:2]).T)))]))
        if self.s >= self.goal_m:
            return None
        target, _ = self.point(self.s + self.lookahead)
        _, heading = self.point(self.s + 0.3)
        d = target - pose[:2]
        v = d / max(float(np.hypot(*d)), 1e-9) * self.speed
        err = wrap_angle(heading - pose[2])
        w = max(-1.0, min(1.0, 2.0 * err))
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], w])
