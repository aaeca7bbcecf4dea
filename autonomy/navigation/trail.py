"""The robot's trail: its recent footprints (pose estimates), the only space behind it
known to be free, and the way back along them that a back-off retraces (``trail_s``).
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import wrap_angle
from autonomy.navigation.config import NavigatorConfig

TRAIL_STEP_M = 0.05
"""The trail keeps a footprint each time the robot has moved this far (``trail_s``)."""
_TRAIL_SAMPLE_M = 0.025
"""A back-off's way back is checked for clearance at points this far apart."""
_TRAIL_GAP_M = 0.15
"""Consecutive footprints farther apart than this were not joined by driving (a pose
correction, a stretch the robot backed along): the way back ends there."""
_RETRACE_AHEAD_M = 0.1
"""A back-off heads for the point this far back along the trail."""


class Trail:
    """A ring of footprints every ``TRAIL_STEP_M``, with their times, big enough for
    ``trail_s`` at twice the cruise speed."""

    def __init__(self, cfg: NavigatorConfig) -> None:
        self.cfg = cfg
        cap = int(math.ceil(2.0 * cfg.trail_s * max(cfg.cruise_speed_mps, cfg.backoff_speed_mps) / TRAIL_STEP_M)) + 16
        self._xy = np.zeros((cap, 2))
        self._times = np.full(cap, -np.inf)
        self._next = 0
        self._last: np.ndarray | None = None
        self._retracing = False
        """The last command backed off along the trail (:meth:`retrace_velocity`)."""

    def clear(self) -> None:
        """Forget every footprint (they were placed through a pose estimate that jumped)."""
        self._times[:] = -np.inf
        self._next = 0
        self._last = None
        self._retracing = False

    def record(self, pose: np.ndarray, t: float) -> None:
        """Add the pose to the trail once it is ``TRAIL_STEP_M`` from the last footprint;
        not after a frame that backed off along the trail (the way back is trail already;
        the retrace reads it back)."""
        retraced, self._retracing = self._retracing, False
        if retraced or self.cfg.trail_s <= 0:
            return
        x, y = float(pose[0]), float(pose[1])
        last = self._last
        if last is not None and (x - last[0]) ** 2 + (y - last[1]) ** 2 < TRAIL_STEP_M * TRAIL_STEP_M:
            return
        k = self._next % len(self._xy)
        self._xy[k] = (x, y)
        self._times[k] = t
        self._next += 1
        self._last = self._xy[k].copy()

    def points(self, t: float) -> np.ndarray:
        """The footprints (world frame, about ``TRAIL_STEP_M`` apart, oldest first) of the
        ``trail_s`` before ``t``."""
        cap = len(self._xy)
        n = min(self._next, cap)
        order = np.arange(self._next - n, self._next) % cap
        return self._xy[order][t - self._times[order] <= self.cfg.trail_s]

    def retrace(self, pose: np.ndarray, t: float) -> np.ndarray:
        """The way back along the trail (as of ``t``) from the pose (world frame, the pose first).

        It starts at the point of the trail nearest the pose (the latest such, on a trail
        that crosses itself), if that lies within ``trail_tolerance_m``, and runs back
        through older footprints for ``backoff_check_m`` at most, ending where
        consecutive footprints lie more than ``_TRAIL_GAP_M`` apart (the robot did not
        drive between them). Just the pose when the trail is off or not near it."""
        cfg = self.cfg
        xy = np.asarray(pose[:2], dtype=np.float64)
        tr = self.points(t) if cfg.trail_s > 0 else np.zeros((0, 2))
        if len(tr) < 2:
            if len(tr) and float(np.hypot(*(tr[0] - xy))) <= cfg.trail_tolerance_m:
                return np.vstack([xy, tr[0]])
            return xy[None, :]
        a, d = tr[:-1], np.diff(tr, axis=0)
        dd = (d * d).sum(axis=1)
        f = np.clip(((xy - a) * d).sum(axis=1) / np.maximum(dd, 1e-12), 0.0, 1.0)
        proj = a + f[:, None] * d
        gap = np.hypot(*(proj - xy).T)
        gap[dd > _TRAIL_GAP_M**2] = np.inf  # not driven between those footprints
        j = len(gap) - 1 - int(np.argmin(gap[::-1]))  # the nearest, the latest of equals
        if not gap[j] <= cfg.trail_tolerance_m:
            return xy[None, :]
        back = tr[j::-1]
        cut = np.flatnonzero(np.hypot(*np.diff(back, axis=0).T) > _TRAIL_GAP_M)
        if len(cut):
            back = back[: cut[0] + 1]
        way = np.vstack([xy, proj[j], back])
        steps = np.hypot(*np.diff(way, axis=0).T)
        keep = np.concatenate([[True], steps > 1e-9])
        way, steps = way[keep], steps[steps > 1e-9]
        cum = np.concatenate([[0.0], np.cumsum(steps)])
        if cum[-1] <= cfg.backoff_check_m:
            return way
        k = int(np.searchsorted(cum, cfg.backoff_check_m))
        w = (cfg.backoff_check_m - cum[k - 1]) / max(cum[k] - cum[k - 1], 1e-12)
        return np.vstack([way[:k], way[k - 1] + w * (way[k] - way[k - 1])])

    def retrace_velocity(self, pose: np.ndarray, pts: np.ndarray, clear: float, t: float) -> np.ndarray:
        """The back-off along :meth:`retrace` (robot-frame velocity; zero where it may
        not): towards the point ``_RETRACE_AHEAD_M`` back along the trail, when that runs
        within 75 degrees of straight back and no point of ``pts`` (robot frame) that the
        way back brings the robot closer to comes within ``clear`` of it."""
        cfg = self.cfg
        way = self.retrace(pose, t)
        if len(way) < 2:
            return np.zeros(3)
        c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
        rel = way - way[0]
        q = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])  # robot frame
        steps = np.hypot(*np.diff(q, axis=0).T)
        cum = np.concatenate([[0.0], np.cumsum(steps)])
        if cum[-1] < TRAIL_STEP_M:
            return np.zeros(3)
        target = np.array([np.interp(min(_RETRACE_AHEAD_M, cum[-1]), cum, q[:, i]) for i in range(2)])
        if abs(wrap_angle(math.atan2(target[1], target[0]) - math.pi)) > math.radians(75.0) + 1e-9:
            return np.zeros(3)
        # Only points within the way back's length plus the clearance can block it.
        pts = pts[pts[:, 0] * pts[:, 0] + pts[:, 1] * pts[:, 1] < (cum[-1] + clear) ** 2] if len(pts) else pts
        if len(pts):
            # The way back, every _TRAIL_SAMPLE_M; a point blocks where the robot would
            # come closer to it than it is now, within the clearance.
            d = np.linspace(0.0, cum[-1], int(math.ceil(cum[-1] / _TRAIL_SAMPLE_M)) + 1)
            samples = np.column_stack([np.interp(d, cum, q[:, 0]), np.interp(d, cum, q[:, 1])])
            gap = np.sqrt(((pts[:, None, :] - samples[None, 1:, :]) ** 2).sum(axis=-1)).min(axis=1)
            now = np.hypot(pts[:, 0], pts[:, 1])
            if np.any((gap < clear) & (gap < now)):
                return np.zeros(3)
        u = target / max(float(np.hypot(target[0], target[1])), 1e-12)
        self._retracing = True
        return np.array([cfg.backoff_speed_mps * u[0], cfg.backoff_speed_mps * u[1], 0.0])
