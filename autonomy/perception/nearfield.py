"""Obstacles closer than the depth camera's minimum range, from the floor it fails to see.

The Kinect returns nothing closer than 0.8 m, so FSPF (BV2012, Section III) and the
obstacle avoidance (Section V) are blind to a person standing right in front of the
robot, who is never sensed and whom the robot would drive into. Yet the camera does
tell that something is there: with the mount's pitch the lowest image rows look at the floor 1.0-1.15 m away,
well inside the sensor's range, and a body in front hides that floor. Where a flat floor
is expected at a valid range but the pixel returns nothing (or a depth below the minimum
range), something occludes that sight line closer than the minimum range (or casts the
IR projector's shadow there, which is narrow: ``min_run_px``) (ours, not in
the papers; range sensors' "no return where the floor should be" is the usual clue, e.g.
cliff and near-obstacle checks on depth cameras).

Per image column (every ``col_step`` pixels), the fraction of such pixels among the
sampled rows of the band where the floor is expected between ``min_range + margin`` and
``band_max_depth_m`` is taken; a column at or above ``min_invalid_fraction`` is blocked.
Where along its sight line the obstacle stands is unknown (between the robot's front and
the point where the ray reaches the minimum range), so a blocked column yields points
every ``point_step_m`` along the down-projected sight line from the robot's edge to that
point; for the image's outer columns, whose sight lines end beside the robot's path, only
along the part beside the path (see :class:`NearField`). Those points are evidence of one frame only: they are not remembered, and the
navigator drops those a mapped wall explains (:meth:`autonomy.navigation.navigator.Navigator.command`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from autonomy.common.constants import KINECT_FOCAL_PX
from autonomy.common.errors import InputError, require_int, require_positive
from autonomy.perception.camera import CameraIntrinsics, CameraMount

REFERENCE_FX_PX = KINECT_FOCAL_PX
"""Focal length (px) that ``min_run_px`` is given for (the Kinect v1, docs/architecture.md)."""


@dataclass(frozen=True)
class NearFieldConfig:
    """Near-field check: which pixels are looked at and when a column counts as blocked."""

    enabled: bool = True
    """False: no near-field points (as the paper: only what FSPF samples)."""
    margin_m: float = 0.1
    """Only pixels whose floor lies at least this far beyond the minimum range count
    (a floor pixel right at the range cut may drop out by noise alone)."""
    band_max_depth_m: float = 1.15
    """... and no farther than this (depth): the band of rows looking at the nearest floor
    (the image's bottom 50 rows on the CoBot mount)."""
    min_invalid_fraction: float = 0.5
    """A column is blocked when at least this fraction of its band pixels return nothing
    (or a depth below the minimum range)."""
    min_run_px: int = 20
    """Blocked columns count only in runs at least this wide (pixels of an f = 580 px
    camera, scaled with the camera's fx): the IR projector's
    shadow beside a surface nearer than the floor leaves no return on the floor too, but
    at most f b (1 / min_range - 1 / band_max_depth) wide (f = 580 px, baseline b =
    7.5 cm: 16.5 px), while a body within the minimum range spans far more (a chair leg
    4 cm wide at 0.8 m: 29 px; a person at 0.6 m: 400 px)."""
    row_step: int = 4
    """Sample every row_step-th row of the band ..."""
    col_step: int = 4
    """... and every col_step-th column."""
    point_step_m: float = 0.05
    """Spacing of the points along a blocked column's sight line."""

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise InputError(f"avoidance.near_field.enabled: expected true or false, got {self.enabled!r}")
        require_positive(self, "avoidance.near_field.", "margin_m", "band_max_depth_m", "point_step_m")
        require_int(self, "avoidance.near_field.", "row_step", "col_step")
        require_int(self, "avoidance.near_field.", "min_run_px", minimum=0)
        f = self.min_invalid_fraction
        if isinstance(f, bool) or not (isinstance(f, (int, float)) and 0.0 < f <= 1.0):
            raise InputError(f"avoidance.near_field.min_invalid_fraction: expected a number in (0, 1], got {f!r}")


class NearField:
    """Blocked columns and their sight-line points for one camera (precomputed rays)."""

    def __init__(
        self,
        intr: CameraIntrinsics,
        mount: CameraMount,
        min_range_m: float,
        robot_radius_m: float,
        cfg: NearFieldConfig = NearFieldConfig(),
        shift_band: bool = False,
    ) -> None:
        """``shift_band``: when no row sees the floor in the configured band, take the
        band of the same width from the nearest floor the camera sees instead of raising
        (a mount the stack corrected at run time, tilted up: the configured band is the
        user's choice for the mount they gave, and checked strictly for it)."""
        if not (math.isfinite(min_range_m) and min_range_m > 0):
            raise InputError(f"near field: the camera's minimum range must be a positive number, got {min_range_m!r}")
        self.cfg = cfg
        self.intr = intr
        self.min_range_m = float(min_range_m)
        self.robot_radius_m = robot_radius_m
        rot, t = mount.rotation(), mount.translation()
        rows = np.arange(intr.height - 1, -1, -cfg.row_step)[::-1]
        cols = np.arange(0, intr.width, cfg.col_step)
        u = (cols - intr.cx) / intr.fx
        v = (rows - intr.cy) / intr.fy
        # Robot-frame direction of each sampled pixel's ray per unit of depth (optical z).
        ray = np.empty((len(rows), len(cols), 3))
        ray[..., 0], ray[..., 1], ray[..., 2] = u[None, :], v[:, None], 1.0
        d = ray @ rot.T
        # Depth at which a flat floor (z = 0) is met: t_z + depth * d_z = 0.
        with np.errstate(divide="ignore", invalid="ignore"):
            floor = np.where(d[..., 2] < 0, -t[2] / d[..., 2], np.inf)
        lo, hi = self.min_range_m + cfg.margin_m, cfg.band_max_depth_m
        expected = (floor >= lo) & (floor <= hi)
        if cfg.enabled and not expected.any() and shift_band and np.isfinite(floor[floor >= lo]).any():
            nearest = float(floor[floor >= lo].min())
            lo, hi = nearest, nearest + (hi - lo)
            expected = (floor >= lo) & (floor <= hi)
        self.band_m = (lo, hi)
        """The floor depths (m) whose pixels are watched."""
        if cfg.enabled and not expected.any():
            # Silently off would be worse: the robot would drive into what it cannot see.
            raise InputError(
                f"avoidance.near_field: no image row sees the floor between "
                f"{self.min_range_m + cfg.margin_m:.2f} and {cfg.band_max_depth_m:.2f} m with this camera mount "
                f"(raise band_max_depth_m, or set enabled = false)"
            )
        keep_rows = expected.any(axis=1)
        self.rows = rows[keep_rows]
        self.cols = cols
        self.expected = expected[keep_rows]
        self._flat = (self.rows[:, None] * intr.width + self.cols[None, :]).astype(np.intp)
        """The sampled pixels' indices into a flattened frame (one gather a frame)."""
        self.n_expected = self.expected.sum(axis=0)
        self.active = bool(cfg.enabled)
        # min_run_px is in pixels of an f = 580 px camera: a shadow's width scales with f.
        self._min_run = max(1, int(math.ceil(cfg.min_run_px * intr.fx / REFERENCE_FX_PX / cfg.col_step)))
        # Each column's sight line: from the camera to where its lowest band pixel's ray
        # reaches the minimum range, down-projected, clipped to start at the robot's edge.
        lowest = d[np.flatnonzero(keep_rows)[-1]] if keep_rows.any() else d[-1]
        a = np.repeat(t[None, :2], len(cols), axis=0)
        b = a + self.min_range_m * lowest[:, :2]
        a = _clip_to_outside(a, b, robot_radius_m)
        # A column whose sight line ends beside the robot's straight path (|y| beyond
        # the robot radius, the image's outer sixth on either side) is taken to be
        # blocked there, beside the path: an obstacle in the path that close would
        # hide the floor of the central columns too (a person is 0.44 m wide). Else
        # passing a person or a box at the avoidance's margin, which puts it inside the
        # minimum range at the image's edge, would stop the robot every time.
        edge = np.abs(b[:, 1]) > robot_radius_m
        with np.errstate(divide="ignore", invalid="ignore"):
            f = np.clip((np.sign(b[:, 1]) * robot_radius_m - a[:, 1]) / (b[:, 1] - a[:, 1]), 0.0, 1.0)
        a[edge] = a[edge] + f[edge, None] * (b[edge] - a[edge])
        self.lines = np.column_stack([a, b])

    def for_mount(self, mount: CameraMount) -> NearField | None:
        """This near field for a mount the stack corrected at run time. A camera tilted up
        may no longer see the configured band of near floor: the nearest floor it sees
        takes its place (``shift_band``; the robot is blind a little farther out). None
        when no floor is in view at all: the caller keeps this one, which watches the
        pixels the floor was last seen in."""
        try:
            return NearField(self.intr, mount, self.min_range_m, self.robot_radius_m, self.cfg, shift_band=True)
        except InputError:
            return None

    def blocked_columns(self, depth: np.ndarray) -> np.ndarray:
        """Boolean per sampled column: is the near floor hidden there?"""
        if not self.active:
            return np.zeros(len(self.cols), dtype=bool)
        if depth.shape != (self.intr.height, self.intr.width):
            raise InputError(f"near field: depth image shape {depth.shape} does not match the camera's {(self.intr.height, self.intr.width)}")
        d = np.ravel(depth).take(self._flat)
        missing = ~(d >= self.min_range_m) & self.expected  # 0, NaN or too near
        frac = missing.sum(axis=0) / np.maximum(self.n_expected, 1)
        blocked = (frac >= self.cfg.min_invalid_fraction) & (self.n_expected > 0)
        return _wide_runs(blocked, self._min_run)

    def sight_lines(self, depth: np.ndarray) -> np.ndarray:
        """(k, 4) robot-frame segments (x0, y0, x1, y1) of the blocked columns' sight lines."""
        return self.lines[self.blocked_columns(depth)]

    def points(self, depth: np.ndarray) -> np.ndarray:
        """(k, 2) robot-frame points every ``point_step_m`` along the blocked sight lines."""
        return line_points(self.sight_lines(depth), self.cfg.point_step_m)


def line_points(lines: np.ndarray, step_m: float) -> np.ndarray:
    """(k, 2) points along each segment (x0, y0, x1, y1), both ends included, at most
    ``step_m`` apart."""
    return line_points_indexed(lines, step_m)[0]


def line_points_indexed(lines: np.ndarray, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`line_points` and, per point, the index of its segment."""
    lines = np.asarray(lines, dtype=np.float64).reshape(-1, 4)
    if not len(lines):
        return np.zeros((0, 2)), np.zeros(0, np.int64)
    a, d = lines[:, :2], lines[:, 2:] - lines[:, :2]
    n = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / step_m).astype(np.int64)) + 1
    seg = np.repeat(np.arange(len(lines)), n)
    frac = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
    return a[seg] + frac[:, None] * d[seg], seg


def _wide_runs(mask: np.ndarray, n: int) -> np.ndarray:
    """``mask`` with its runs of True shorter than ``n`` cleared."""
    if n <= 1 or not mask.any():
        return mask
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    starts, ends = np.flatnonzero(np.diff(m) == 1), np.flatnonzero(np.diff(m) == -1)
    out = np.zeros_like(mask)
    for a, b in zip(starts, ends, strict=True):
        if b - a >= n:
            out[a:b] = True
    return out


def _clip_to_outside(a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """Where each segment a-b leaves the disc of ``radius`` round the origin (a itself if
    outside; b if the segment never leaves it): nothing can stand inside the robot."""
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    ad = np.einsum("ij,ij->i", a, d)
    aa = np.einsum("ij,ij->i", a, a)
    disc = np.maximum(ad * ad - dd * (aa - radius * radius), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(dd > 0, (-ad + np.sqrt(disc)) / dd, 1.0)
    s = np.where(aa >= radius * radius, 0.0, np.clip(s, 0.0, 1.0))
    return a + s[:, None] * d
