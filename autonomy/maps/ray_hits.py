"""Ray hits: the first of a set of lines (e.g. scene lines) a ray from a point meets.

:func:`ray_hit` / :func:`rays_hit` intersect rays with a set of lines; :func:`ray_hit_nb`
is the same inside compiled code, and :func:`bearing_index` / :func:`ray_hit_indexed` bin
the lines by pseudo-angle around the origin so a ray is only tested against its bin's
lines (the same answer). Used on the scene lines of BV2012, Algorithm 2
(:mod:`autonomy.maps.analytic_raycast`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from autonomy.common.errors import InputError

__all__ = ["ray_hit", "rays_hit", "ray_hit_nb", "bearing_index", "ray_hit_indexed"]


@numba.njit(cache=True, inline="always")
def _pseudo_angle(x: float, y: float) -> float:
    """A number in [0, 4) that grows with atan2(y, x) from -pi (the "diamond angle": no
    trigonometry); opposite directions are 2 apart. (0, 0) gives 0."""
    a = abs(x) + abs(y)
    if a == 0.0:
        return 0.0
    p = y / a
    return p + 1.0 if x >= 0.0 else 3.0 - p


def _check_segments(segments: np.ndarray) -> np.ndarray:
    seg = np.ascontiguousarray(segments, dtype=np.float64)
    if seg.ndim != 2 or seg.shape[1] != 4:
        raise InputError(f"segments must have shape (N, 4) [x1, y1, x2, y2], got {seg.shape}")
    return seg


@numba.njit(cache=True, inline="always")
def _segment_hit(lines: np.ndarray, i: int, ox: float, oy: float, dx: float, dy: float, tb: float) -> float:
    """``t`` where the ray (ox, oy) + t (dx, dy) meets line ``i``, if it does at 0 <= t < tb;
    else inf (parallel lines are not hit)."""
    ax = lines[i, 0] - ox
    ay = lines[i, 1] - oy
    ex = lines[i, 2] - lines[i, 0]
    ey = lines[i, 3] - lines[i, 1]
    den = dx * ey - dy * ex  # cross(d, e)
    if den == 0.0:
        return np.inf
    t = (ax * ey - ay * ex) / den  # cross(a, e) / cross(d, e)
    if t < 0.0 or t >= tb:
        return np.inf
    u = (ax * dy - ay * dx) / den  # cross(a, d) / cross(d, e)
    if u < 0.0 or u > 1.0:
        return np.inf
    return t


@numba.njit(cache=True)
def ray_hit_nb(lines: np.ndarray, ox: float, oy: float, dx: float, dy: float) -> tuple[int, float]:
    """:func:`ray_hit` inside compiled code (lines already checked): every line tested."""
    best = -1
    tb = np.inf
    for i in range(lines.shape[0]):
        t = _segment_hit(lines, i, ox, oy, dx, dy, tb)
        if t < tb:
            best = i
            tb = t
    return best, tb


@numba.njit(cache=True)
def bearing_index(lines: np.ndarray, ox: float, oy: float, nb: int) -> tuple[np.ndarray, np.ndarray]:
    """The lines each of ``nb`` equal bins of pseudo-angle around (ox, oy) may hold, as
    (offsets (nb + 1,), line ids) in ascending id order per bin: a ray needs testing only
    against its bin's lines. Each line's bins are its endpoints' arc widened by a bin on
    either side (rounding); a line through (or ending at) the origin goes in every bin."""
    m = lines.shape[0]
    first = np.empty(m, np.int64)
    count = np.empty(m, np.int64)
    offsets = np.zeros(nb + 1, np.int64)
    scale = nb / 4.0
    for i in range(m):
        ax = lines[i, 0] - ox
        ay = lines[i, 1] - oy
        bx = lines[i, 2] - ox
        by = lines[i, 3] - oy
        p0 = _pseudo_angle(ax, ay)
        d = _pseudo_angle(bx, by) - p0
        if d > 2.0:
            d -= 4.0
        elif d <= -2.0:
            d += 4.0
        if (ax == 0.0 and ay == 0.0) or (bx == 0.0 and by == 0.0) or abs(d) > 1.99:
            first[i] = 0
            count[i] = nb
        else:
            start = p0 if d >= 0.0 else p0 + d
            b0 = int(math.floor(start * scale)) - 1
            count[i] = min(int(math.floor((start + abs(d)) * scale)) + 1 - b0 + 1, nb)
            first[i] = b0
        for j in range(count[i]):
            offsets[(first[i] + j) % nb + 1] += 1
    for b in range(nb):
        offsets[b + 1] += offsets[b]
    ids = np.empty(offsets[nb], np.int64)
    fill = offsets[:nb].copy()
    for i in range(m):
        for j in range(count[i]):
            b = (first[i] + j) % nb
            ids[fill[b]] = i
            fill[b] += 1
    return offsets, ids


@numba.njit(cache=True)
def ray_hit_indexed(
    lines: np.ndarray, offsets: np.ndarray, ids: np.ndarray, ox: float, oy: float, dx: float, dy: float
) -> tuple[int, float]:
    """:func:`ray_hit_nb` against only the lines of the ray's bin of
    :func:`bearing_index` (built at ``ox, oy``): the same answer."""
    nb = offsets.shape[0] - 1
    b = int(_pseudo_angle(dx, dy) * (nb / 4.0)) % nb
    best = -1
    tb = np.inf
    for k in range(offsets[b], offsets[b + 1]):
        i = ids[k]
        t = _segment_hit(lines, i, ox, oy, dx, dy, tb)
        if t < tb:
            best = i
            tb = t
    return best, tb


@numba.njit(cache=True)
def _rays_hit_kernel(
    lines: np.ndarray, ox: float, oy: float, dirs: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    k = dirs.shape[0]
    idx = np.empty(k, np.int64)
    ts = np.empty(k)
    for r in range(k):
        i, t = ray_hit_nb(lines, ox, oy, dirs[r, 0], dirs[r, 1])
        idx[r] = i
        ts[r] = t
    return idx, ts


def ray_hit(lines: np.ndarray, ox: float, oy: float, dx: float, dy: float) -> tuple[int, float]:
    """First line hit by the ray (ox, oy) + t (dx, dy), t >= 0: ``(index, t)`` or ``(-1, inf)``.

    ``t`` is in units of the direction (a distance when it is a unit vector). Lines parallel
    to the ray are not hit.
    """
    i, t = ray_hit_nb(_check_segments(lines), float(ox), float(oy), float(dx), float(dy))
    return int(i), float(t)


def rays_hit(lines: np.ndarray, ox: float, oy: float, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`ray_hit` for K directions ``dirs`` (K, 2): ``(idx (K,) int64, t (K,))``."""
    d = np.ascontiguousarray(dirs, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 2:
        raise InputError(f"rays_hit: dirs must have shape (K, 2), got {d.shape}")
    return _rays_hit_kernel(_check_segments(lines), float(ox), float(oy), d)
