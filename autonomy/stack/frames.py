"""The frame guard: dropped, corrupt, invalid and stale depth frames told apart and
counted (a camera driver's failures are the robot's to survive, not to be fooled by)."""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import relative_pose
from autonomy.perception.camera import frame_checks

#: Stale frames are told by comparing every this-many-th pixel with the last frame's.
STALE_SAMPLE_STRIDE = 7
#: ... while the odometry says the robot moved more than this since those pixels first
#: came (a still scene may repeat; a stuck driver's old frame stays old when it stops).
STALE_MOTION_M = 1e-3
STALE_MOTION_RAD = 1e-3


def moved_more_than_noise(inc: np.ndarray) -> bool:
    """Whether a pose difference (dx, dy, dtheta) is more than ``STALE_MOTION_*``."""
    return bool(math.hypot(inc[0], inc[1]) > STALE_MOTION_M or abs(inc[2]) > STALE_MOTION_RAD)


class FrameGuard:
    """What was wrong with each frame (``fault``) and how many of each kind (``rejected``).

    ``fault``: '' nothing; dropped or stale (not used); invalid (no valid pixel; used:
    the near field reads it as blocked right ahead); corrupt (NaN or infinite pixels;
    used without them)."""

    def __init__(self) -> None:
        self.fault = ""
        self.rejected = {"dropped": 0, "stale": 0, "invalid": 0, "corrupt": 0}
        self._last_key: np.ndarray | None = None
        self._maybe_stale = False
        self._new_pixels = False
        self._pixels_odom: np.ndarray | None = None
        """The odometry when the last frame's pixels first came (the stale test's origin)."""

    def reset(self) -> None:
        """Forget the last frame (a new start)."""
        self._last_key = None
        self._pixels_odom = None

    def begin(self) -> None:
        """A new frame: nothing wrong with it yet."""
        self.fault = ""
        self._maybe_stale = False
        self._new_pixels = False

    def reject(self, why: str) -> None:
        """The frame is not used (``dropped`` or ``stale``)."""
        self.fault = why
        self.rejected[why] += 1

    def check(self, depth: np.ndarray) -> np.ndarray:
        """The depth image to use: non-finite pixels (a broken driver) zeroed and the frame
        counted corrupt; no valid pixel counted invalid; whether it repeats the last
        frame's pixels noted for :meth:`stale`."""
        finite = np.isfinite(depth)
        if not finite.all():
            depth = np.where(finite, depth, np.float32(0.0)).astype(np.float32, copy=False)
            self.fault = "corrupt"
            self.rejected["corrupt"] += 1
        valid, repeats = frame_checks(depth, STALE_SAMPLE_STRIDE, self._last_key)
        if not valid:
            # Nothing valid: a camera that fails, or something closer than its minimum
            # range filling the view; the two look alike, and the near field reads both
            # as "blocked right ahead" (it never drives into either). Counted, and used.
            self.fault = "invalid"
            self.rejected["invalid"] += 1
        self._maybe_stale = valid and repeats
        self._new_pixels = valid and not repeats
        self._last_key = depth.ravel()[::STALE_SAMPLE_STRIDE].copy() if valid else None
        return depth

    def stale(self, odom: np.ndarray, moved: bool) -> bool:
        """Whether this frame is stale: the same pixels as the last one while the wheels
        turned (``moved``: this frame's odometry increment was more than noise); counted.
        Motion is measured from where these pixels first came, not from the last frame:
        a robot that stopped (blind for the refused frames) would otherwise take a stuck
        driver's old view for its own and pull its belief back to it."""
        if self._maybe_stale and self._pixels_odom is not None:
            moved = moved_more_than_noise(relative_pose(self._pixels_odom, odom))
        if self._maybe_stale and moved:
            self.reject("stale")
            return True
        return False

    def note_odometry(self, odom: np.ndarray) -> None:
        """After the frame's odometry: new pixels' origin for the stale test."""
        if self._new_pixels:
            self._pixels_odom = odom.copy()
            self._new_pixels = False
