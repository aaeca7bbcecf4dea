"""Plane boundaries: the convex hull of a plane's inliers, in the plane (Section II-B1).

The paper computes "plane boundaries" after each detection without saying how; here a
plane's boundary is the convex hull of its inlier points in 2D plane coordinates, lifted
back onto the plane. The hull is computed in O(n) with a column trick: the inliers are
binned into columns ``column_m`` wide along the plane's first axis, only each column's
lowest and highest point is kept, and Andrew's monotone chain runs on those (at most two
per column). The result is within ``column_m`` of the exact hull of the points used;
planes with more than ``max_points`` inliers use every k-th of them.
"""

from __future__ import annotations

import numba
import numpy as np

#: Columns are widened so that no hull uses more than this many.
MAX_COLUMNS = 4096


def plane_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (u, v) spanning the plane, (u, v, n) right-handed.

    For planes that are not near-horizontal, u is horizontal and v points up the plane
    (so walls get "along" and "up" axes when the frame's z is up).
    """
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    ref = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(ref, n)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return u, v


@numba.njit(cache=True)
def _cross2(o0, o1, a0, a1, b0, b1):  # pragma: no cover - numba
    return (a0 - o0) * (b1 - o1) - (a1 - o1) * (b0 - o0)


@numba.njit(cache=True)
def _hull_indexed(pts, idx, n, c, u, v, column_m, max_columns, stride):  # pragma: no cover - numba
    """Convex hull (K, 2) in plane coordinates of ``pts[idx[:n:stride]]``, counter-clockwise."""
    if n == 0:
        return np.zeros((0, 2))
    c0, c1, c2 = c[0], c[1], c[2]
    u0, u1, u2 = u[0], u[1], u[2]
    v0, v1, v2 = v[0], v[1], v[2]
    amin, amax = 1e300, -1e300
    for k in range(0, n, stride):
        i = idx[k]
        a = (pts[i, 0] - c0) * u0 + (pts[i, 1] - c1) * u1 + (pts[i, 2] - c2) * u2
        amin = min(amin, a)
        amax = max(amax, a)
    w = max(column_m, (amax - amin) / (max_columns - 1) + 1e-12)
    inv_w = 1.0 / w
    ncol = int((amax - amin) * inv_w) + 1
    lo_a = np.empty(ncol)
    lo_b = np.full(ncol, 1e300)
    hi_a = np.empty(ncol)
    hi_b = np.full(ncol, -1e300)
    for k in range(0, n, stride):
        i = idx[k]
        x = pts[i, 0] - c0
        y = pts[i, 1] - c1
        z = pts[i, 2] - c2
        a = x * u0 + y * u1 + z * u2
        b = x * v0 + y * v1 + z * v2
        j = min(int((a - amin) * inv_w), ncol - 1)
        if b < lo_b[j]:
            lo_b[j] = b
            lo_a[j] = a
        if b > hi_b[j]:
            hi_b[j] = b
            hi_a[j] = a
    # Candidates sorted by a: the columns are in order; inside a column sort its two.
    cand = np.empty((2 * ncol, 2))
    m = 0
    for j in range(ncol):
        if lo_b[j] > 1e299:
            continue
        if lo_a[j] < hi_a[j] or (lo_a[j] == hi_a[j] and lo_b[j] <= hi_b[j]):
            cand[m, 0], cand[m, 1] = lo_a[j], lo_b[j]
            cand[m + 1, 0], cand[m + 1, 1] = hi_a[j], hi_b[j]
        else:
            cand[m, 0], cand[m, 1] = hi_a[j], hi_b[j]
            cand[m + 1, 0], cand[m + 1, 1] = lo_a[j], lo_b[j]
        m += 2
    # Neighbouring columns can interleave in a by less than a column width: sort exactly.
    order = np.argsort(cand[:m, 0], kind="mergesort")
    s = cand[:m][order]
    # Andrew's monotone chain.
    hull = np.empty((2 * m + 1, 2))
    k = 0
    for i in range(m):
        while k >= 2 and _cross2(hull[k - 2, 0], hull[k - 2, 1], hull[k - 1, 0], hull[k - 1, 1], s[i, 0], s[i, 1]) <= 0.0:
            k -= 1
        hull[k, 0], hull[k, 1] = s[i, 0], s[i, 1]
        k += 1
    t = k + 1
    for i in range(m - 2, -1, -1):
        while k >= t and _cross2(hull[k - 2, 0], hull[k - 2, 1], hull[k - 1, 0], hull[k - 1, 1], s[i, 0], s[i, 1]) <= 0.0:
            k -= 1
        hull[k, 0], hull[k, 1] = s[i, 0], s[i, 1]
        k += 1
    return hull[: max(k - 1, 1)].copy()


def hull_2d(points2d: np.ndarray) -> np.ndarray:
    """Exact convex hull (K, 2) of 2D points, counter-clockwise (reference / small inputs)."""
    p = np.unique(np.asarray(points2d, dtype=np.float64), axis=0)
    if len(p) < 3:
        return p
    lower: list[np.ndarray] = []
    for q in p:
        while len(lower) >= 2 and _cross(lower[-2], lower[-1], q) <= 0:
            lower.pop()
        lower.append(q)
    upper: list[np.ndarray] = []
    for q in p[::-1]:
        while len(upper) >= 2 and _cross(upper[-2], upper[-1], q) <= 0:
            upper.pop()
        upper.append(q)
    return np.array(lower[:-1] + upper[:-1])


def _cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


def polygon_area(poly2d: np.ndarray) -> float:
    """Area of a simple 2D polygon (shoelace)."""
    if len(poly2d) < 3:
        return 0.0
    x, y = poly2d[:, 0], poly2d[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def plane_frame(normal: np.ndarray, rho: float, origin: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plane's 2D frame: ``origin`` projected onto n . p = rho, and the basis (u, v)."""
    u, v = plane_basis(normal)
    n = np.asarray(normal, dtype=np.float64)
    c = np.asarray(origin, dtype=np.float64)
    return c - (c @ n - rho) * n, u, v


def plane_hull(
    points: np.ndarray,
    idx: np.ndarray,
    normal: np.ndarray,
    rho: float,
    centroid: np.ndarray,
    column_m: float = 0.01,
    max_points: int = 50_000,
) -> np.ndarray:
    """Boundary polygon (K, 3) of the inliers ``points[idx]``, on the plane n . p = rho.

    At most ``max_points`` inliers are used (every k-th, in their order): for a cloud
    from a depth image that keeps every image row and thins the columns, so the hull
    loses at most k pixel spacings at its left and right ends.
    """
    c, u, v = plane_frame(normal, rho, centroid)
    stride = max(1, -(-len(idx) // max(int(max_points), 1)))
    h2 = _hull_indexed(points, np.asarray(idx, dtype=np.int64), len(idx), c, u, v, float(column_m), MAX_COLUMNS, stride)
    return c + h2[:, :1] * u + h2[:, 1:2] * v


def lift_hull(hull2d: np.ndarray, normal: np.ndarray, rho: float, origin: np.ndarray) -> np.ndarray:
    """2D plane coordinates (about ``origin`` projected on the plane) back to 3D points."""
    c, u, v = plane_frame(normal, rho, origin)
    return c + hull2d[:, :1] * u + hull2d[:, 1:2] * v


def to_plane_coords(pts3: np.ndarray, normal: np.ndarray, rho: float, origin: np.ndarray) -> np.ndarray:
    """3D points (K, 3) to 2D coordinates in the plane's basis about ``origin``."""
    c, u, v = plane_frame(normal, rho, origin)
    d = np.asarray(pts3, dtype=np.float64) - c
    return np.column_stack([d @ u, d @ v])


def fan_triangles(k: int) -> np.ndarray:
    """Triangle fan (k - 2, 3) of a convex polygon with k vertices."""
    if k < 3:
        return np.zeros((0, 3), dtype=np.int64)
    i = np.arange(1, k - 1)
    return np.column_stack([np.zeros(k - 2, dtype=np.int64), i, i + 1])


__all__ = [
    "plane_basis",
    "plane_hull",
    "hull_2d",
    "polygon_area",
    "lift_hull",
    "to_plane_coords",
    "fan_triangles",
]
