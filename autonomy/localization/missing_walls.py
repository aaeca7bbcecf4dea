"""Walls the map puts in the camera's view that the camera sees past.

The map tests of :mod:`autonomy.localization.health` judge FSPF's plane points, which leave out the
floor. In an open hall a robot may see nothing but floor within the camera's range:
with no plane points there is no evidence, and a belief a few metres away beside a wall
goes unquestioned while the robot drives on it, for tens of metres. Yet the floor is
evidence too. A
pixel whose ray, from the belief, meets a mapped wall before the floor should return
that wall, or something nearer (people and furniture the map does not hold); a return
from farther away, the floor beyond where the wall should stand, says that the wall is
not there (ours; the seen-through test of :func:`autonomy.localization.health.explain_points` for
every pixel, floor included).

A pixel that returns nothing says nothing here: the Kinect returns nothing beyond its
range, but also nothing closer than its minimum range (a door jamb the robot passes, a
person right in front, a thick wall's end where the map has a line), nothing at grazing
incidence and nothing in the projector's shadow beside a depth edge.

On a grid (``stride_u_px`` columns, ``stride_v_px`` rows) each pixel's ray (through the
camera mount) is followed from the camera's position at the belief to the first of the
scene's lines. The pixel **expects a wall** at the planar depth z of that hit when z lies
between ``min_range + margin_m`` and ``max_range - margin_m`` (a pose a few decimetres
off moves a wall across the range's ends), the ray does not meet the floor first, and it
meets the wall less than ``max_incidence_rad`` from the wall's normal and at least
``end_margin_m`` from a free end of its line (one no other line joins) or from a
silhouette (a ray ``end_margin_m`` to either side at the wall's distance meets nothing,
or something more than ``tol_m`` farther off the wall's line: a pillar's side seen
edge-on, where a belief a decimetre or two off moves the pillar across the ray). Of those that
returned a depth, a pixel **sees past** the wall when every valid depth within
``window_px`` of it in its row is farther than ``z + tol_m + tol_per_m2 z^2`` (a pose a
little off moves a wall's end by a pixel or two; the Kinect's depth noise grows with
z squared).

The frame's seen-past fraction (of the pixels expecting a wall that returned) is NaN
(no evidence) with fewer than ``min_returned`` such pixels;
:class:`autonomy.localization.health.HealthMonitor` says lost when its short-term average stays high.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from autonomy.common.errors import InputError, require_int, require_non_negative, require_positive
from autonomy.maps.raycast import bearing_index, ray_hit_indexed
from autonomy.perception.camera import CameraIntrinsics

__all__ = ["MissingWallsConfig", "missing_walls"]

#: Bins of direction around the camera for the ray casts (about half a degree each).
BEARING_BINS = 512
#: Lines whose end points lie this close continue one wall (:func:`_free_ends`).
END_JOIN_M = 0.02
#: A point this close to a line's extension lies on the same wall (:func:`_near_silhouette`).
SAME_WALL_M = 0.05


@dataclass(frozen=True)
class MissingWallsConfig:
    """Which pixels expect a wall and when one sees past it."""

    stride_u_px: int = 16
    """Every this-many-th column ..."""
    stride_v_px: int = 8
    """... and row (40 x 60 rays on a 640 x 480 frame: a wall 2.5 m away leaves about 60
    rows of floor within range below its base, 3.5 m away about 15)."""
    margin_m: float = 0.4
    """A wall counts only between the camera's range ends moved in by this."""
    max_incidence_rad: float = math.radians(65.0)
    """... and seen at most this far from its normal (the simulated Kinect begins to drop
    pixels at 70 degrees)."""
    tol_m: float = 0.3
    """A return farther than the wall by more than this ..."""
    tol_per_m2: float = 0.01
    """... plus this times the wall's depth squared (m per m^2) sees past it."""
    window_px: int = 2
    """Every valid depth within this many pixels in the row must be past the wall."""
    end_margin_m: float = 0.3
    """A ray that meets its line less than this from an end where no other line joins
    (a wall's free end), or from a silhouette (a pillar's side, a corner seen edge-on),
    expects nothing: a belief a few centimetres off moves such an edge across the rays
    beside it, and past it the camera sees the floor (0 = every ray). A 0.5 m pillar 3.5 m
    ahead then gives no evidence: seen from a belief 13 cm and 1.4 degrees off, 55 % of
    its pixels saw past it, and the robot stopped to look round (a real floor)."""
    min_returned: int = 10
    """Frames with fewer pixels expecting a wall that returned carry no evidence."""

    def __post_init__(self) -> None:
        require_int(self, "recovery.missing.", "stride_u_px", minimum=1)
        require_int(self, "recovery.missing.", "stride_v_px", minimum=1)
        require_int(self, "recovery.missing.", "window_px", minimum=0)
        require_int(self, "recovery.missing.", "min_returned", minimum=1)
        require_non_negative(self, "recovery.missing.", "margin_m", "tol_m", "tol_per_m2", "end_margin_m")
        require_positive(self, "recovery.missing.", "max_incidence_rad")


@numba.njit(cache=True)
def _missing_kernel(depth, lines, px, py, pth, rot, trans, fx, fy, cx, cy, su, sv, zlo, zhi, cos_max, tol_m, tol_q, win, end_m):  # pragma: no cover - numba
    """(expecting, returned, past) pixel counts (module docstring). ``px, py, pth``: the
    belief's robot pose; ``rot``, ``trans``: robot_from_camera."""
    h, w = depth.shape
    c, s = math.cos(pth), math.sin(pth)
    ox = px + c * trans[0] - s * trans[1]
    oy = py + s * trans[0] + c * trans[1]
    cam_h = trans[2]
    # Each ray is tested only against the lines in its direction.
    offsets, ids = bearing_index(lines, ox, oy, BEARING_BINS)
    free = _free_ends(lines, END_JOIN_M)
    n_exp = 0
    n_ret = 0
    n_past = 0
    for v in range(sv // 2, h, sv):
        for u in range(su // 2, w, su):
            x = (u - cx) / fx
            y = (v - cy) / fy
            rx = rot[0, 0] * x + rot[0, 1] * y + rot[0, 2]
            ry = rot[1, 0] * x + rot[1, 1] * y + rot[1, 2]
            rz = rot[2, 0] * x + rot[2, 1] * y + rot[2, 2]
            hn = math.sqrt(rx * rx + ry * ry)
            if hn <= 0.0:
                continue
            if rz < 0.0 and -cam_h / rz < zlo:
                continue  # the floor comes before any wall that could count: no ray to cast
            dx = (c * rx - s * ry) / hn
            dy = (s * rx + c * ry) / hn
            bj, t = ray_hit_indexed(lines, offsets, ids, ox, oy, dx, dy)
            if bj < 0:
                continue
            z = t / hn  # planar depth of the wall along this pixel's ray
            if z < zlo or z > zhi:
                continue
            if rz < 0.0 and -cam_h / rz < z:
                continue  # the floor comes first
            ex = lines[bj, 2] - lines[bj, 0]
            ey = lines[bj, 3] - lines[bj, 1]
            L = math.sqrt(ex * ex + ey * ey)
            cos_inc = abs(dx * ey - dy * ex) / L if L > 0.0 else 0.0
            if cos_inc < cos_max:
                continue  # grazing: the camera may drop it
            along = ((ox + t * dx - lines[bj, 0]) * ex + (oy + t * dy - lines[bj, 1]) * ey) / L
            if (free[bj, 0] and along < end_m) or (free[bj, 1] and along > L - end_m):
                continue  # near the wall's end: a small pose error moves the end across the ray
            if end_m > 0.0 and _near_silhouette(lines, offsets, ids, ox, oy, dx, dy, t, bj, end_m, tol_m):
                continue  # beside a pillar's side or a corner seen edge-on: the same
            n_exp += 1
            far = z + tol_m + tol_q * z * z
            returned = False
            short = False
            for uu in range(max(0, u - win), min(w, u + win + 1)):
                d = depth[v, uu]
                if d > 0.0 and math.isfinite(d):
                    returned = True
                    if d <= far:
                        short = True
                        break
            if returned:
                n_ret += 1
                if not short:
                    n_past += 1
    return n_exp, n_ret, n_past


@numba.njit(cache=True)
def _near_silhouette(lines, offsets, ids, ox, oy, dx, dy, t, bj, end_m, tol_m):  # pragma: no cover - numba
    """Whether a ray that meets line ``bj`` at distance ``t`` lies within ``end_m`` of a
    silhouette: one of the two rays ``end_m`` to either side of it at that distance
    meets nothing, or meets something more than ``tol_m`` farther that does not lie on
    ``bj``'s wall (within ``SAME_WALL_M`` of its line, extended: a wall the map draws in
    pieces, seen obliquely). A pillar's sides and a corner seen edge-on are such edges
    though no line ends there."""
    ax, ay = lines[bj, 0], lines[bj, 1]
    ex, ey = lines[bj, 2] - ax, lines[bj, 3] - ay
    L = math.sqrt(ex * ex + ey * ey)
    a = end_m / t
    ca, sa = math.cos(a), math.sin(a)
    for sgn in (-1.0, 1.0):
        ddx = ca * dx - sgn * sa * dy
        ddy = sgn * sa * dx + ca * dy
        j, t2 = ray_hit_indexed(lines, offsets, ids, ox, oy, ddx, ddy)
        if j < 0:
            return True
        if t2 > t + tol_m:
            hx, hy = ox + t2 * ddx - ax, oy + t2 * ddy - ay
            if abs(hx * ey - hy * ex) / L > SAME_WALL_M:
                return True
    return False


@numba.njit(cache=True)
def _free_ends(lines, join_m):  # pragma: no cover - numba
    """(M, 2) whether each line's first and second end point is a wall's end: no other
    line has an end point within ``join_m`` of it (a map draws one wall as several
    collinear pieces, and a corner as two lines that share an end). The end points are
    swept in order of x, each compared with those within ``join_m`` of it in x."""
    m = lines.shape[0]
    free = np.ones((m, 2), dtype=np.bool_)
    xs = np.empty(2 * m)
    for i in range(m):
        xs[2 * i] = lines[i, 0]
        xs[2 * i + 1] = lines[i, 2]
    order = np.argsort(xs)
    j2 = join_m * join_m
    for oi in range(2 * m):
        p = order[oi]
        i, a = p // 2, p % 2
        px, py = lines[i, 2 * a], lines[i, 2 * a + 1]
        for oj in range(oi + 1, 2 * m):
            q = order[oj]
            k, b = q // 2, q % 2
            qx, qy = lines[k, 2 * b], lines[k, 2 * b + 1]
            if qx - px > join_m:
                break
            if k != i and (qx - px) * (qx - px) + (qy - py) * (qy - py) <= j2:
                free[i, a] = False
                free[k, b] = False
    return free


def missing_walls(
    depth: np.ndarray,
    lines: np.ndarray,
    pose: np.ndarray,
    intr: CameraIntrinsics,
    robot_from_camera: np.ndarray,
    min_range_m: float,
    max_range_m: float,
    cfg: MissingWallsConfig = MissingWallsConfig(),
) -> tuple[int, int, int]:
    """(expecting, returned, seen past) pixels of ``depth`` (planar metres, 0 or
    non-finite invalid) at the robot ``pose`` (x, y, theta) against the scene's ``lines``
    (M, 4) world frame (module docstring)."""
    d = np.ascontiguousarray(depth, dtype=np.float32)
    if d.shape != (intr.height, intr.width):
        raise InputError(f"missing walls: depth image expected {intr.height}x{intr.width}, got shape {d.shape}")
    rc = np.ascontiguousarray(robot_from_camera, dtype=np.float64)
    ln = np.ascontiguousarray(lines, dtype=np.float64).reshape(-1, 4)
    p = np.asarray(pose, dtype=np.float64)
    n_exp, n_ret, n_past = _missing_kernel(
        d, ln, float(p[0]), float(p[1]), float(p[2]), rc[:3, :3].copy(), rc[:3, 3].copy(),
        float(intr.fx), float(intr.fy), float(intr.cx), float(intr.cy), int(cfg.stride_u_px), int(cfg.stride_v_px),
        float(min_range_m + cfg.margin_m), float(max_range_m - cfg.margin_m), float(math.cos(cfg.max_incidence_rad)),
        float(cfg.tol_m), float(cfg.tol_per_m2), int(cfg.window_px), float(cfg.end_margin_m),
    )
    return int(n_exp), int(n_ret), int(n_past)
