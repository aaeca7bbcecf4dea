"""What a lost robot has seen (ours): the relocalization's scan, the modes of the map
search, and the near field's points of the last look round, in the dead-reckoning frame;
read by the search (:mod:`autonomy.stack.lost`) and by the motion
(:mod:`autonomy.stack.search_motion`)."""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import points_from_frame, points_in_frame
from autonomy.localization.relocalization import Scan
from autonomy.localization.straight_runs import on_straight_runs
from autonomy.navigation.navigator import Navigator
from autonomy.perception.nearfield import line_points_indexed
from autonomy.stack.config import StackConfig
from autonomy.stack.state import StackState

#: While relocalizing, what the robot saw this long ago or less stands in for the map's
#: walls where the camera cannot look: the scan's points, and what the near field shows
#: (something closer than the camera's minimum range), in the dead-reckoning frame. About
#: one look round, so a drive that sets out after it knows what stands beside the robot.
#: Older points are not: dead reckoning a degree or two off over a few metres' drive puts
#: what the robot saw before 0.1-0.2 m from where it is, and a 0.9 m door seen half a
#: minute and two drives ago looks 0.6 m wide to a robot standing in it.
SEEN_KEEP_S = 15.0
#: While relocalizing, the scan's points on walls are counted again at most this often
#: (a few milliseconds for thousands of points; the scan grows by a frame at a time).
WALL_COUNT_EVERY_S = 0.5


class LostView:
    """The scan, the modes and the near field's recent points of a lost robot."""

    def __init__(self, cfg: StackConfig, state: StackState, navigator: Navigator | None) -> None:
        self.cfg = cfg
        self.state = state
        self.navigator = navigator
        cam, rl = cfg.camera, cfg.recovery.relocalization
        # The camera's rays start ahead of the robot's centre: from the centre, a ray
        # through a door close by its jamb crosses the wall.
        self.sensor_xy = (cam.mount.forward_m, cam.mount.lateral_m)
        self.scan = Scan(rl.scan_cell_m, rl.max_scan_points, self.sensor_xy, rl.floor_cell_m)
        self.modes: list[tuple[np.ndarray, float]] = []
        """Relocalization modes as (map-from-odometry transform, score), best first."""
        self.started_t = 0.0
        """When the robot last began to look round (the alarm, or the end of a drive)."""
        self._walls: tuple[float, int, int] | None = None
        self._near_seen = np.zeros((0, 7))

    def clear(self, t: float) -> None:
        """Lost at ``t``: nothing seen yet."""
        self.scan.clear()
        self.modes = []
        self.started_t = t
        self._walls = None
        self._near_seen = np.zeros((0, 7))

    def look_again(self, t: float) -> None:
        """A drive is over: look round again from here (the scan keeps what it saw on the way)."""
        self.started_t = t
        self.scan.turned_rad = 0.0

    def keep_near(self, near_lines: np.ndarray | None, t: float) -> None:
        """Keep this frame's near-field points (dead-reckoning frame, each with the ends of
        its sight line and its time) for ``SEEN_KEEP_S``. Looking round in place, the
        robot sees nothing closer than 0.8 m; a pillar beside it hides the floor only
        while the camera faces it, and the drive that sets out afterwards would turn into
        it."""
        odom = self.state.odom
        kept = self._near_seen
        kept = kept[kept[:, 6] >= t - SEEN_KEEP_S]
        lines = np.zeros((0, 4)) if near_lines is None else np.asarray(near_lines, dtype=np.float64).reshape(-1, 4)
        if len(lines):
            pts, line = line_points_indexed(lines, self.cfg.avoidance.near_field.point_step_m)
            ends = points_from_frame(odom, lines.reshape(-1, 2)).reshape(-1, 4)
            w = np.column_stack([points_from_frame(odom, pts), ends[line], np.full(len(pts), t)])
            kept = np.vstack([w, kept])  # newest first: np.unique keeps the first of a cell
            key = np.floor(kept[:, :2] / self.scan.cell_m).astype(np.int64)
            _, first = np.unique(key[:, 0] * 1_000_003 + key[:, 1], return_index=True)
            kept = kept[np.sort(first)]
        self._near_seen = kept

    def seen_now(self, t: float, pose: np.ndarray | None = None) -> np.ndarray:
        """What the robot has seen in the last ``SEEN_KEEP_S`` while relocalizing,
        relative to it now: the scan's points, and the near field's. With the ``pose`` of
        the mode a drive is planned on, the near field's points whose sight line a wall
        of that mode's map explains are left out, as the navigator leaves out this
        frame's (:meth:`autonomy.navigation.surroundings.Surroundings.near_points`): the map's wall counts
        there already, where it stands, whereas the sight line's points lie anywhere
        from the robot's edge to the camera's minimum range, and kept from a look round
        beside a wall they ring the robot (a robot put down in an office by its door
        could not turn to the door)."""
        odom = self.state.odom
        pts = self.scan.recent_in_robot_frame(odom, t - SEEN_KEEP_S)
        kept = self._near_seen
        if not len(kept):
            return pts
        near = points_in_frame(odom, kept[:, :2])
        if pose is not None and self.navigator is not None:
            ends = points_in_frame(odom, kept[:, 2:6].reshape(-1, 2)).reshape(-1, 4)
            lines, inverse = np.unique(ends, axis=0, return_inverse=True)
            explained = self.navigator.walls_explain(pose, lines, with_seen=False)
            near = near[~explained[inverse.reshape(-1)]]
        return np.vstack([pts, near])

    def lacks_walls(self, t: float) -> bool:
        """Whether the scan is too small to search (``min_scan_points``) or holds too
        little wall (``min_wall_points`` of its points on straight runs at least
        ``min_wall_m`` long, :func:`autonomy.localization.straight_runs.on_straight_runs`; counted at
        most every ``WALL_COUNT_EVERY_S`` while it grows)."""
        rc = self.cfg.recovery.relocalization
        n = len(self.scan.points)
        if n < rc.min_scan_points:
            return True
        if rc.min_wall_points == 0:
            return False
        if self._walls is None or t - self._walls[0] >= WALL_COUNT_EVERY_S or n < self._walls[1]:
            self._walls = (t, n, int(on_straight_runs(self.scan.points, rc.min_wall_m).sum()))
        return self._walls[2] < rc.min_wall_points

    def swept(self) -> bool:
        """Whether the robot has looked round since it last set out (``min_sweep_deg``)."""
        return self.scan.turned_rad >= math.radians(self.cfg.recovery.relocalization.min_sweep_deg)
