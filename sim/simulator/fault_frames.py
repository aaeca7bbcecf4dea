"""What the robot receives while a sensor fault is active (:class:`FrameFaults`).

The camera faults (blackout, dropped, NaN and stale frames) replace the depth frame; a
wheel slip adds forward motion to the odometry increment that did not happen. Both act on
the frame the simulator produced, never on the world, and keep the frame's true pose.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from autonomy.common.geometry import compose_pose
from sim.simulator.fault_record import ActiveFault
from sim.simulator.robot import Odometry
from sim.simulator.step import SimFrame


class FrameFaults:
    """Filters each frame by the faults active now. It remembers the last frame (the one a
    stale burst repeats) and the odometry pose before the step (which a slip moves on),
    and draws from the faults' ``rng`` only while a fault that needs it is active."""

    def __init__(self, rng: np.random.Generator, odometry: Odometry, t: float) -> None:
        self.rng = rng
        self.odometry = odometry
        self._t = float(t)
        self._last_depth: np.ndarray | None = None
        self._stale: np.ndarray | None = None
        self._odom_before: np.ndarray | None = None

    def before_step(self, t: float) -> None:
        """The time of the tick about to step (a slip's increment is its speed times the step)."""
        self._t = float(t)

    def hold_odometry(self) -> None:
        """Remember the odometry pose before the step: a slip composes its altered increment onto it."""
        self._odom_before = self.odometry.pose.copy()

    def end(self, kind: str) -> None:
        """Forget what an ending fault of ``kind`` kept (the stale frame, the odometry pose)."""
        if kind == "stale":
            self._stale = None
        elif kind == "slip":
            self._odom_before = None

    def filter(self, frame: SimFrame, active: dict[str, ActiveFault]) -> SimFrame:
        """What the robot receives: depth replaced (zeros / NaN / stale copy / None when
        dropped) and odometry increment altered during slip bursts. frame.pose stays the truth."""
        if not active:
            self._last_depth = frame.depth
            return frame
        depth, inc = frame.depth, frame.increment
        if "stale" in active:
            if self._stale is None:
                self._stale = self._last_depth if self._last_depth is not None else depth
            if self._stale is not None:
                depth = self._stale.copy()
        else:
            self._last_depth = depth
        if "corrupt_nan" in active and depth is not None:
            p = active["corrupt_nan"].params
            depth = depth.copy()
            depth[self.rng.random(depth.shape) < p.nan_fraction] = np.nan
            depth[self.rng.choice(depth.shape[0], size=min(p.nan_rows, depth.shape[0]), replace=False)] = np.nan
        if "blackout" in active and depth is not None:
            depth = np.zeros_like(depth)
        if "dropped" in active and self.rng.random() < active["dropped"].params.drop_probability:
            depth = None
        if "slip" in active and inc is not None:
            dt = frame.t - self._t
            inc = inc + np.array([active["slip"].params.slip_speed_mps * dt, 0.0, 0.0])
            if self._odom_before is not None:
                self.odometry.pose = compose_pose(self._odom_before, inc)
        if depth is frame.depth and inc is frame.increment:
            return frame
        return replace(frame, depth=depth, increment=inc)
