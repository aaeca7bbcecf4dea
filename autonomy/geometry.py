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
