"""What the navigator knows stands round the robot beyond this frame's obstacles: the
map's walls near it (placed through the pose estimate), those in the camera's blind
spots, the walls seen before, and the memory of obstacles out of view
(:mod:`autonomy.navigation.obstacle_memory`); and which near-field sight lines a wall
explains.
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import segments_near_points
from autonomy.navigation.avoidance import AvoidanceConfig
from autonomy.navigation.config import MEMORY_KEEP_MARGIN_M, NavigatorConfig
from autonomy.navigation.obstacle_memory import update_memory
from autonomy.perception.camera import DepthCamera
from autonomy.perception.nearfield import line_points

WALL_STEP_M = 0.03
"""Spacing of the points that stand in for the map's walls (:meth:`Surroundings.map_points`)."""
_LOCAL_MARGIN_M = 1.0


def wall_points(walls: np.ndarray, step_m: float) -> np.ndarray:
    """(n, 2) points along each wall segment, both ends included, at most ``step_m`` apart."""
    a, d = walls[:, :2], walls[:, 2:] - walls[:, :2]
    L = np.hypot(d[:, 0], d[:, 1])
    n = np.maximum(1, np.ceil(L / step_m).astype(np.int64)) + 1
    seg = np.repeat(np.arange(len(L)), n)
    frac = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
    return a[seg] + frac[:, None] * d[seg]


def in_camera_view(
    x: np.ndarray, y: np.ndarray, camera: DepthCamera, fov_fraction: float = 1.0, near_pad_m: float = 0.0, far_pad_m: float = 0.0
) -> np.ndarray:
    """Which points (x, y relative to the camera, robot axes) lie inside the camera's
    horizontal view: within ``fov_fraction`` of its field of view and between its minimum
    and maximum range (narrowed by the pads). Occlusion is not considered."""
    r = np.hypot(x, y)
    return (
        (np.abs(np.arctan2(y, x)) < 0.5 * fov_fraction * camera.fov_h_rad)
        & (r > camera.min_range_m + near_pad_m)
        & (r < camera.max_range_m - far_pad_m)
    )


class Surroundings:
    """The map's walls near the robot and the obstacle memory.

    ``walls``: the map's wall segments (K, 4), world frame, or None (no map).
    """

    def __init__(self, cfg: NavigatorConfig, avoid: AvoidanceConfig, camera: DepthCamera, walls: np.ndarray | None) -> None:
        self.cfg = cfg
        self.avoid = avoid
        self.camera = camera
        self._wall_pts = None if walls is None else wall_points(walls, WALL_STEP_M)
        self._local = np.zeros((0, 2))
        self._local_centre: np.ndarray | None = None
        self._local_radius = 0.0
        self.seen = np.zeros((0, 2))
        """Points seen before (robot frame) given to this frame's command (:meth:`map_points`)."""
        self._mem = np.zeros((0, 2))
        self._mem_t = np.zeros(0)
        self._mem_all = np.zeros((0, 2))

    @property
    def remembered(self) -> np.ndarray:
        """Every point the memory holds, robot frame, as of the last :meth:`remember`
        (``backoff_memory_s``: for the back-off's check of the way back only)."""
        return self._mem_all

    def forget(self) -> None:
        """Forget the obstacle memory (it was placed through a pose estimate that jumped)."""
        self._mem = np.zeros((0, 2))
        self._mem_t = np.zeros(0)
        self._mem_all = np.zeros((0, 2))

    # -- obstacle memory ----------------------------------------------------------------
    def remember(self, pose: np.ndarray, obstacles: np.ndarray, t: float) -> np.ndarray:
        """Fold this frame's obstacles into the memory; all known obstacles, robot frame.

        Remembered points in the region the camera sees now are replaced by the current
        observation (people move on); points right in front of the robot but closer than
        the camera's minimum range persist until that place is seen again, for
        ``memory_blind_s`` at most; those near the robot for ``memory_beside_s``; the
        others for ``memory_s``. Each sensed point's
        shadow (``shadow_m``) is remembered with it. Points stay remembered for
        ``backoff_memory_s`` for the back-off's check of the way back only
        (:attr:`remembered`).
        """
        cfg, cam = self.cfg, self.camera
        obs = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
        if cfg.memory_s <= 0:
            self._mem_all = np.zeros((0, 2))
            return obs
        # Wall marks reach at least the wall points' spacing, so that they join up.
        reach = max(1, math.ceil(WALL_STEP_M / cfg.memory_cell_m - 1e-9))
        self._mem, self._mem_t, out, recent = update_memory(
            self._mem,
            self._mem_t,
            obs,
            float(pose[0]),
            float(pose[1]),
            float(pose[2]),
            float(t),
            cfg.memory_cell_m,
            max(cfg.memory_s, cfg.backoff_memory_s, cfg.memory_beside_s),
            cfg.memory_s,
            cfg.memory_radius_m + MEMORY_KEEP_MARGIN_M,
            cfg.memory_radius_m,
            cam.forward_m,
            # A little inside the view's edges, so what is replaced was really seen.
            0.5 * 0.9 * cam.fov_h_rad,
            cam.min_range_m + 0.1,
            cam.max_range_m - 0.2,
            cam.min_range_m + 0.1,
            self.avoid.radius_m + 0.2,
            cfg.memory_beside_s,
            cfg.memory_beside_m,
            cfg.memory_blind_s,
            cfg.shadow_m,
            self._shadow_walls(pose, reach),
            reach,
        )
        self._mem_all = out
        return out[recent]

    def _shadow_walls(self, pose: np.ndarray, reach: int) -> np.ndarray:
        """The map's wall points (world frame, exactly as stored, so that each lands on
        the same cell every frame) where the memory's shadows end: those whose marks,
        ``reach`` cells round each, can touch a cell within the memory's reach of the
        pose (``WALL_STEP_M`` apart, closer than a cell)."""
        if self.cfg.shadow_m <= 0 or self._wall_pts is None:
            return np.zeros((0, 2))
        radius = self.cfg.memory_radius_m + MEMORY_KEEP_MARGIN_M + (reach + 1) * self.cfg.memory_cell_m * math.sqrt(2.0)
        return self._local_walls(pose, radius)

    def blind_blocked(self, obstacles: np.ndarray) -> bool:
        """Whether an obstacle point lies in the path ahead closer than the camera sees."""
        if self.cfg.memory_s <= 0 or not len(obstacles):
            return False
        o = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
        rng = np.hypot(o[:, 0] - self.camera.forward_m, o[:, 1])
        ahead = (o[:, 0] > 0.0) & (np.abs(o[:, 1]) < self.avoid.radius_m)
        return bool(np.any(ahead & (rng < self.camera.min_range_m + 0.1)))

    # -- the map's walls ----------------------------------------------------------------
    def map_points(self, pose: np.ndarray, radius_m: float, with_seen: bool = True) -> np.ndarray:
        """The map's walls within ``radius_m`` of the pose as points every
        ``WALL_STEP_M``, in the robot frame: what is known to be there even where the
        camera cannot look. The walls are sampled once; the points near the robot are
        cached and re-selected only after it has moved ``_LOCAL_MARGIN_M``. The points
        this frame's command was given as :attr:`seen` within the radius join them:
        a pose on a wrong relocalization mode puts the map's walls where none are, and the
        robot's own sight of the walls around it is then the only knowledge it has
        (``with_seen`` False: the map's alone)."""
        rel = self.near_walls(pose, radius_m)
        c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
        pts = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])
        seen = self.seen
        if with_seen and len(seen):
            pts = np.vstack([pts, seen[seen[:, 0] * seen[:, 0] + seen[:, 1] * seen[:, 1] < radius_m * radius_m]])
        return pts

    def near_walls(self, pose: np.ndarray, radius_m: float) -> np.ndarray:
        """:meth:`map_points` relative to the robot's position, in world axes (the map's alone)."""
        return self._local_walls(pose, radius_m) - np.asarray(pose[:2], dtype=np.float64)

    def _local_walls(self, pose: np.ndarray, radius_m: float) -> np.ndarray:
        """The map's wall points (world frame) closer than ``radius_m`` to the robot."""
        if self._wall_pts is None or not len(self._wall_pts):
            return np.zeros((0, 2))
        xy = np.asarray(pose[:2], dtype=np.float64)
        c0, r0 = self._local_centre, self._local_radius
        if c0 is None or radius_m > r0 - _LOCAL_MARGIN_M or math.hypot(xy[0] - c0[0], xy[1] - c0[1]) > r0 - radius_m:
            r0 = max(radius_m, r0 - _LOCAL_MARGIN_M) + _LOCAL_MARGIN_M
            w = self._wall_pts
            self._local = w[np.hypot(w[:, 0] - xy[0], w[:, 1] - xy[1]) < r0]
            self._local_centre, self._local_radius = xy.copy(), r0
        rel = self._local - xy
        return self._local[rel[:, 0] * rel[:, 0] + rel[:, 1] * rel[:, 1] < radius_m * radius_m]

    def map_blind_spots(self, pose: np.ndarray) -> np.ndarray:
        """Map wall points within ``map_blind_spots_m`` that the camera cannot see now
        (outside its view cone or closer than its minimum range), robot frame."""
        cfg = self.cfg
        if cfg.map_blind_spots_m <= 0:
            return np.zeros((0, 2))
        return self.out_of_view(self.map_points(pose, cfg.map_blind_spots_m))

    def out_of_view(self, pts: np.ndarray) -> np.ndarray:
        """The points (robot frame) the camera cannot see now: outside its view cone or
        closer than its minimum range."""
        if not len(pts):
            return pts
        return pts[~in_camera_view(pts[:, 0] - self.camera.forward_m, pts[:, 1], self.camera)]

    # -- the near field -----------------------------------------------------------------
    def near_points(self, pose: np.ndarray, near_lines: np.ndarray | None) -> np.ndarray:
        """Points along the near-field sight lines (:mod:`autonomy.perception.nearfield`) that no
        mapped wall explains, robot frame: a sight line with a map wall within
        ``near_wall_tol_m`` of it is hidden by that wall (a door frame the robot passes
        close to), which ``map_blind_spots_m`` covers already."""
        lines = np.zeros((0, 4)) if near_lines is None else np.asarray(near_lines, dtype=np.float64).reshape(-1, 4)
        if not len(lines):
            return np.zeros((0, 2))
        return line_points(lines[~self.walls_explain(pose, lines)], self.avoid.near_field.point_step_m)

    def walls_explain(self, pose: np.ndarray, lines: np.ndarray, with_seen: bool = True) -> np.ndarray:
        """Per near-field sight line (robot frame, (K, 4)): whether a wall passes within
        ``near_wall_tol_m`` of it at the pose (the map's, and with ``with_seen`` the
        :attr:`seen` ones: :meth:`map_points`)."""
        lines = np.asarray(lines, dtype=np.float64).reshape(-1, 4)
        if not len(lines):
            return np.zeros(0, dtype=bool)
        reach = float(np.max(np.hypot(lines[:, 2], lines[:, 3]))) + self.cfg.near_wall_tol_m
        return segments_near_points(lines, self.map_points(pose, reach, with_seen), self.cfg.near_wall_tol_m)
