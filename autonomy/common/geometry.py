"""Plane geometry shared by the stack and the simulator: angles, poses, segments.

Each helper is written once here and imported wherever it is needed. Every function
computes its documented expression in a fixed order, so a caller that switches to it
gets the same floating-point results it computed inline before (a closed loop stays
bit-for-bit identical on the same seed). Numba versions exist only where a kernel
calls the helper; they are the same expressions.

Poses are (x, y, theta) in the world frame (REP-103: x forward, y left, theta
counter-clockwise); segments are rows ``x1, y1, x2, y2``.
"""

from __future__ import annotations

import math

import numba
import numpy as np


def wrap_angle(a: float) -> float:
    """Angle ``a`` wrapped to [-pi, pi] as ``atan2(sin a, cos a)``."""
    return math.atan2(math.sin(a), math.cos(a))


def wrap_angles(a: np.ndarray) -> np.ndarray:
    """Element-wise :func:`wrap_angle` of an array."""
    return np.arctan2(np.sin(a), np.cos(a))


@numba.njit(cache=True, inline="always")
def wrap_angle_nb(a: float) -> float:  # pragma: no cover - numba
    """:func:`wrap_angle` for numba kernels."""
    return math.atan2(math.sin(a), math.cos(a))


def relative_pose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pose b expressed in the frame of pose a: the increment (dx, dy, dtheta)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    dth = math.atan2(math.sin(b[2] - a[2]), math.cos(b[2] - a[2]))
    return np.array([c * dx + s * dy, -s * dx + c * dy, dth])


def compose_pose(a: np.ndarray, inc: np.ndarray) -> np.ndarray:
    """Pose a followed by the robot-frame increment inc."""
    c, s = math.cos(a[2]), math.sin(a[2])
    th = a[2] + inc[2]
    return np.array(
        [a[0] + c * inc[0] - s * inc[1], a[1] + s * inc[0] + c * inc[1], math.atan2(math.sin(th), math.cos(th))]
    )


def sensor_view(pose: np.ndarray, pts: np.ndarray, sensor_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pose of a sensor mounted at ``sensor_xy`` (robot frame, facing as the robot)
    on a robot at ``pose``, and robot-frame points ``pts`` (N, 2) relative to it
    (C-contiguous): the camera's rays start there, not at the robot's centre."""
    o = np.asarray(sensor_xy, dtype=np.float64).reshape(2)
    at = compose_pose(np.asarray(pose, dtype=np.float64), np.array([o[0], o[1], 0.0]))
    return at, np.ascontiguousarray(np.asarray(pts, dtype=np.float64).reshape(-1, 2) - o)


def points_in_frame(pose: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """World points (N, 2) expressed in the frame of ``pose`` (C-contiguous)."""
    p = np.asarray(pose, dtype=np.float64)
    d = np.asarray(xy, dtype=np.float64).reshape(-1, 2) - p[:2]
    c, s = math.cos(p[2]), math.sin(p[2])
    return np.ascontiguousarray(np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]]))


def rectangle_corners(x: float, y: float, yaw: float, length: float, width: float) -> np.ndarray:
    """(4, 2) corners, counter-clockwise, of a ``length`` x ``width`` rectangle centred at
    (x, y) with its length along ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]]) * (0.5 * length, 0.5 * width)
    return np.column_stack([x + c * local[:, 0] - s * local[:, 1], y + s * local[:, 0] + c * local[:, 1]])


def points_from_frame(pose: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Points (N, 2) given in the frame of ``pose``, in world coordinates (the inverse of
    :func:`points_in_frame`)."""
    p = np.asarray(pose, dtype=np.float64)
    q = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    c, s = math.cos(p[2]), math.sin(p[2])
    return np.column_stack([p[0] + c * q[:, 0] - s * q[:, 1], p[1] + s * q[:, 0] + c * q[:, 1]])


def polyline_clear(path: np.ndarray, points: np.ndarray, length_m: float, clearance_m: float) -> bool:
    """Whether the first ``length_m`` of the polyline ``path`` (K, 2) passes farther than
    ``clearance_m`` from every one of ``points`` (N, 2)."""
    path = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(path) < 2 or not len(pts):
        return True
    seg = np.hstack([path[:-1], path[1:]])
    lengths = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    start = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    keep = start < length_m
    if not keep.any():
        return True
    seg, lengths, start = seg[keep], lengths[keep], start[keep]
    # The last segment kept is cut at length_m.
    f = np.clip((length_m - start[-1]) / max(lengths[-1], 1e-12), 0.0, 1.0)
    seg[-1, 2:] = seg[-1, :2] + f * (seg[-1, 2:] - seg[-1, :2])
    return bool(np.min(point_segment_distance(pts, seg)) > clearance_m)


def point_segment_projection(p: np.ndarray, segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Point p (2,) projected on each segment (N, 4): the fraction t in [0, 1] along it
    of the nearest point, and the distance to that point. A zero-length segment is its
    end point (t = 0)."""
    a, b = segments[:, :2], segments[:, 2:]
    d = b - a
    L2 = np.einsum("ij,ij->i", d, d)
    t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    q = a + t[:, None] * d
    return t, np.hypot(p[0] - q[:, 0], p[1] - q[:, 1])


def point_segment_distance(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distance from each point to each segment: points (..., 2), segments (N, 4) ->
    (..., N); a single point (2,) gives (N,). A zero-length segment is its end point."""
    p = np.asarray(points)
    if p.ndim == 1:
        return point_segment_projection(p, segments)[1]
    a, b = segments[:, :2], segments[:, 2:]
    d = b - a
    L2 = np.einsum("ij,ij->i", d, d)
    t = np.clip(np.einsum("...ij,ij->...i", p[..., None, :] - a, d) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    q = a + t[..., None] * d
    return np.hypot(p[..., None, 0] - q[..., 0], p[..., None, 1] - q[..., 1])


def crosses_any(p: np.ndarray, q: np.ndarray, walls: np.ndarray) -> bool:
    """Whether segment p-q properly crosses any wall (N, 4): the two segments' ends lie
    strictly on either side of each other's line (touching or collinear: no)."""
    a, b = walls[:, :2], walls[:, 2:]

    def orient(u, v, w):
        return (v[..., 0] - u[..., 0]) * (w[..., 1] - u[..., 1]) - (v[..., 1] - u[..., 1]) * (w[..., 0] - u[..., 0])

    o1 = orient(p[None, :], q[None, :], a)
    o2 = orient(p[None, :], q[None, :], b)
    o3 = orient(a, b, p[None, :])
    o4 = orient(a, b, q[None, :])
    return bool(np.any((o1 * o2 < 0) & (o3 * o4 < 0)))


@numba.njit(cache=True, inline="always")
def segments_cross_nb(ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float, dy: float) -> bool:  # pragma: no cover - numba
    """:func:`crosses_any` for one pair, segment a-b against segment c-d, in numba kernels
    (the same orientation products: c-d's line first, then a-b's)."""
    vx, vy = dx - cx, dy - cy
    d1 = vx * (ay - cy) - vy * (ax - cx)
    d2 = vx * (by - cy) - vy * (bx - cx)
    if d1 * d2 >= 0.0:
        return False
    ux, uy = bx - ax, by - ay
    d3 = ux * (cy - ay) - uy * (cx - ax)
    d4 = ux * (dy - ay) - uy * (dx - ax)
    return d3 * d4 < 0.0


def segments_near_points(segments: np.ndarray, points: np.ndarray, tol_m: float) -> np.ndarray:
    """Per segment (K, 4): whether any of ``points`` (M, 2) lies closer than ``tol_m`` to it.

    Each point's distance is ``hypot(r - s d)`` with ``r`` the point less the segment's
    start, ``d`` the segment, and ``s = clip(r . d / max(d . d, 1e-12), 0, 1)``, in that
    order; a segment stops at its first point that is near. This is the navigator's near
    field test's own expression (a zero-length segment through the 1e-12 floor, not
    :func:`_point_segment_nb`'s branch), computed to the last bit as the same expression
    in numpy gives it, so a point at ``tol_m`` to the last bit is near or not exactly as
    the expression says."""
    seg = np.ascontiguousarray(segments, dtype=np.float64).reshape(-1, 4)
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    out = np.zeros(len(seg), dtype=np.bool_)
    if len(seg) and len(pts):
        _segments_near_points_nb(seg, pts, float(tol_m), out)
    return out


@numba.njit(cache=True)
def _segments_near_points_nb(seg: np.ndarray, pts: np.ndarray, tol: float, out: np.ndarray) -> None:  # pragma: no cover - numba
    for k in range(seg.shape[0]):
        ax, ay = seg[k, 0], seg[k, 1]
        dx, dy = seg[k, 2] - ax, seg[k, 3] - ay
        dd = max(dx * dx + dy * dy, 1e-12)
        for m in range(pts.shape[0]):
            rx, ry = pts[m, 0] - ax, pts[m, 1] - ay
            s = min(max((rx * dx + ry * dy) / dd, 0.0), 1.0)
            if math.hypot(rx - s * dx, ry - s * dy) < tol:
                out[k] = True
                break


# --------------------------------------------------------------------------- segment distances


def segment_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact Euclidean distance between paired 2D segments ``a[i]`` and ``b[i]`` (M x 4 each):
    0 where they cross, else the least of the four end-point-to-segment distances."""
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    out = np.empty(a.shape[0])
    _segment_distances_nb(a, b, out)
    return out


@numba.njit(cache=True, inline="always")
def _point_segment_nb(px: float, py: float, ax: float, ay: float, bx: float, by: float) -> float:  # pragma: no cover - numba
    dx, dy = bx - ax, by - ay
    L2 = dx * dx + dy * dy
    t = 0.0
    if L2 > 0.0:
        t = min(1.0, max(0.0, ((px - ax) * dx + (py - ay) * dy) / L2))
    return math.hypot(px - (ax + t * dx), py - (ay + t * dy))


@numba.njit(cache=True)
def segment_distance_nb(ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float, dy: float) -> float:  # pragma: no cover - numba
    """Exact distance between segments a-b and c-d (0 when they cross)."""
    if segments_cross_nb(ax, ay, bx, by, cx, cy, dx, dy):
        return 0.0
    return min(
        min(_point_segment_nb(ax, ay, cx, cy, dx, dy), _point_segment_nb(bx, by, cx, cy, dx, dy)),
        min(_point_segment_nb(cx, cy, ax, ay, bx, by), _point_segment_nb(dx, dy, ax, ay, bx, by)),
    )


@numba.njit(cache=True)
def _segment_distances_nb(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - numba
    for i in range(a.shape[0]):
        out[i] = segment_distance_nb(a[i, 0], a[i, 1], a[i, 2], a[i, 3], b[i, 0], b[i, 1], b[i, 2], b[i, 3])


@numba.njit(cache=True)
def _bucket_walls(walls: np.ndarray, x0: float, y0: float, size: float, nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - numba
    counts = np.zeros(nx * ny + 1, dtype=np.int64)
    for pass_ in range(2):
        fill = counts.copy() if pass_ == 1 else counts
        idx = np.empty(counts[-1] if pass_ == 1 else 0, dtype=np.int64)
        for w in range(walls.shape[0]):
            i0 = max(0, int((min(walls[w, 0], walls[w, 2]) - x0) / size))
            i1 = min(nx - 1, int((max(walls[w, 0], walls[w, 2]) - x0) / size))
            j0 = max(0, int((min(walls[w, 1], walls[w, 3]) - y0) / size))
            j1 = min(ny - 1, int((max(walls[w, 1], walls[w, 3]) - y0) / size))
            for j in range(j0, j1 + 1):
                for i in range(i0, i1 + 1):
                    b = j * nx + i
                    if pass_ == 0:
                        counts[b + 1] += 1
                    else:
                        idx[fill[b]] = w
                        fill[b] += 1
        if pass_ == 0:
            for b in range(nx * ny):
                counts[b + 1] += counts[b]
        else:
            return counts, idx
    return counts, np.empty(0, dtype=np.int64)


@numba.njit(cache=True)
def _clearances_nb(
    q: np.ndarray, walls: np.ndarray, offsets: np.ndarray, idx: np.ndarray,
    x0: float, y0: float, size: float, nx: int, ny: int, cutoff: float, out: np.ndarray,
) -> None:  # pragma: no cover - numba
    for k in range(q.shape[0]):
        ax, ay, bx, by = q[k, 0], q[k, 1], q[k, 2], q[k, 3]
        i0 = max(0, int((min(ax, bx) - cutoff - x0) / size))
        i1 = min(nx - 1, int((max(ax, bx) + cutoff - x0) / size))
        j0 = max(0, int((min(ay, by) - cutoff - y0) / size))
        j1 = min(ny - 1, int((max(ay, by) + cutoff - y0) / size))
        best = cutoff
        for j in range(j0, j1 + 1):
            for i in range(i0, i1 + 1):
                b = j * nx + i
                for t in range(offsets[b], offsets[b + 1]):
                    w = idx[t]
                    d = segment_distance_nb(ax, ay, bx, by, walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3])
                    if d < best:
                        best = d
        out[k] = best


class WallIndex:
    """Walls bucketed on a square grid, for exact segment-to-wall clearances of many
    query segments (each query looks only at the buckets within its cutoff)."""

    def __init__(self, walls: np.ndarray, bucket_m: float = 1.0):
        w = np.ascontiguousarray(np.asarray(walls, dtype=np.float64).reshape(-1, 4))
        self.walls = w
        self.bucket_m = float(bucket_m)
        if w.shape[0]:
            self.x0 = float(min(w[:, 0].min(), w[:, 2].min()))
            self.y0 = float(min(w[:, 1].min(), w[:, 3].min()))
            x1 = float(max(w[:, 0].max(), w[:, 2].max()))
            y1 = float(max(w[:, 1].max(), w[:, 3].max()))
        else:
            self.x0 = self.y0 = x1 = y1 = 0.0
        self.nx = int((x1 - self.x0) / self.bucket_m) + 1
        self.ny = int((y1 - self.y0) / self.bucket_m) + 1
        self.offsets, self.idx = _bucket_walls(w, self.x0, self.y0, self.bucket_m, self.nx, self.ny)

    def clearances(self, segments: np.ndarray, cutoff_m: float) -> np.ndarray:
        """(M,) exact distance from each query segment (M, 4) (or point, as a zero-length
        segment) to the nearest wall, capped at ``cutoff_m``."""
        q = np.ascontiguousarray(np.asarray(segments, dtype=np.float64).reshape(-1, 4))
        out = np.empty(q.shape[0])
        _clearances_nb(q, self.walls, self.offsets, self.idx, self.x0, self.y0, self.bucket_m, self.nx, self.ny, float(cutoff_m), out)
        return out
