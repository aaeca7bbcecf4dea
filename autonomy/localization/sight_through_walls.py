"""Sight through walls for the relocalization's modes (:mod:`autonomy.localization.relocalization`):
how many scan points, seen from where the camera stood, lie behind a map wall their ray
crosses when the scan is placed at a pose. Clutter can only hide walls, never show what
lies behind them, so a point seen through a wall speaks against a pose. The ray is
marched over the free space's distance transform and each grid hit confirmed on the map's
segments (:func:`segment_index` finds those around it); numba kernels over plain arrays,
shared out over the cores by pose."""

from __future__ import annotations

import math

import numba
import numpy as np

#: Cell size of the segment index that confirms the grid's wall hits exactly.
SEGMENT_INDEX_CELL_M = 1.0


def segment_index(seg: np.ndarray, x0: float, y0: float, cell: float, ny: int, nx: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR index (start (ny * nx + 1,), ids) of the segments passing through each cell of
    a (ny, nx) grid with lower-left corner (x0, y0): the segments of cell k are
    ``ids[start[k]:start[k + 1]]``."""
    seg = np.asarray(seg, dtype=np.float64).reshape(-1, 4)
    n = np.maximum(2, np.ceil(np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) / (0.25 * cell)).astype(np.int64) + 1)
    sid = np.repeat(np.arange(len(seg)), n)
    t = np.concatenate([np.linspace(0.0, 1.0, k) for k in n]) if len(seg) else np.zeros(0)
    px = seg[sid, 0] + t * (seg[sid, 2] - seg[sid, 0])
    py = seg[sid, 1] + t * (seg[sid, 3] - seg[sid, 1])
    j = np.clip(np.floor((px - x0) / cell).astype(np.int64), 0, nx - 1)
    k = np.clip(np.floor((py - y0) / cell).astype(np.int64), 0, ny - 1)
    key = np.unique((k * nx + j) * max(len(seg), 1) + sid)
    cells, ids = key // max(len(seg), 1), key % max(len(seg), 1)
    start = np.searchsorted(cells, np.arange(ny * nx + 1)).astype(np.int64)
    return start, ids.astype(np.int64)


@numba.njit(cache=True, inline="always")
def _crosses(seg, start, ids, ix0, iy0, inv_icell, iny, inx, ax, ay, ux, uy, hx, hy, end, qx, qy, depth, end_m):  # pragma: no cover - numba
    """Whether the ray from (ax, ay) along unit (ux, uy) meets a segment before ``end``,
    at least ``end_m`` from the segment's ends, that the ray's point (qx, qy) lies more
    than ``depth`` behind (from the segment's line), among the indexed segments around
    (hx, hy) (the cell of a grid wall hit and its eight neighbours)."""
    cj = int(math.floor((hx - ix0) * inv_icell))
    ck = int(math.floor((hy - iy0) * inv_icell))
    for dk in range(-1, 2):
        for dj in range(-1, 2):
            j, k = cj + dj, ck + dk
            if j < 0 or k < 0 or j >= inx or k >= iny:
                continue
            cell = k * inx + j
            for q in range(start[cell], start[cell + 1]):
                m = ids[q]
                px, py = seg[m, 0], seg[m, 1]
                ex, ey = seg[m, 2] - px, seg[m, 3] - py
                den = ux * ey - uy * ex
                if den == 0.0:
                    continue
                wx, wy = px - ax, py - ay
                tt = (wx * ey - wy * ex) / den
                lam = (wx * uy - wy * ux) / den
                if 0.0 <= tt <= end and -1e-9 <= lam <= 1.0 + 1e-9:
                    length = math.sqrt(ex * ex + ey * ey)
                    if end_m > 0.0 and (lam * length < end_m or (1.0 - lam) * length < end_m):
                        continue
                    if abs(ex * (qy - py) - ey * (qx - px)) > depth * length:
                        return True
    return False


@numba.njit(cache=True)
def _through_count(
    dist, ox, oy, inv_cell, x, y, c, s, origins, pts, margin, depth, seg, start, ids, ix0, iy0, inv_icell, iny, inx, end_m
):  # pragma: no cover - numba
    """How many robot-frame points ``pts``, seen from robot-frame ``origins``, lie behind
    a wall their ray crosses at pose (x, y, theta = atan2(s, c)): more than ``margin``
    along the ray and more than ``depth`` from the wall's line. The scan's points are
    placed through dead reckoning: a degree of drift moves a point 4 m away 7 cm off
    its wall, which is 0.4 m along its ray when the wall is seen 10 degrees off it.
    The ray is marched over the distance transform (sphere tracing: each step is the
    free distance around the sample less a cell, so no wall cell is stepped over); a
    wall cell has distance 0. A grid wall is a cell thick, so a ray through a door
    beside its jamb can clip one: each hit is confirmed on the map's segments around
    it (``segment_index``; none given, ``start`` empty: the grid decides, along the
    ray), crossing it at least ``end_m`` from its ends. Rays leaving the grid meet no
    wall."""
    ny, nx = dist.shape
    cell = 1.0 / inv_cell
    exact = start.shape[0] > 1
    n = 0
    for i in range(pts.shape[0]):
        ax = x + c * origins[i, 0] - s * origins[i, 1]
        ay = y + s * origins[i, 0] + c * origins[i, 1]
        dx = c * (pts[i, 0] - origins[i, 0]) - s * (pts[i, 1] - origins[i, 1])
        dy = s * (pts[i, 0] - origins[i, 0]) + c * (pts[i, 1] - origins[i, 1])
        r = math.sqrt(dx * dx + dy * dy)
        if r <= margin:
            continue
        ux, uy = dx / r, dy / r
        t, end = 0.0, r - margin
        # A wall just before ``end`` can lie in a grid cell the ray enters just after it.
        limit = end + 2.0 * cell if exact else end
        while t < limit:
            j = int(math.floor((ax + t * ux - ox) * inv_cell))
            k = int(math.floor((ay + t * uy - oy) * inv_cell))
            if j < 0 or k < 0 or j >= nx or k >= ny:
                break
            d = dist[k, j]
            if d < 0.5 * cell:
                if not exact or _crosses(
                    seg, start, ids, ix0, iy0, inv_icell, iny, inx, ax, ay, ux, uy, ax + t * ux, ay + t * uy, end,
                    ax + r * ux, ay + r * uy, depth, end_m,
                ):
                    n += 1
                    break
            t += max(d - cell, 0.5 * cell)
    return n


@numba.njit(cache=True, parallel=True)
def _through_counts(
    dist, ox, oy, inv_cell, poses, origins, pts, margin, depth, seg, start, ids, ix0, iy0, inv_icell, iny, inx, end_m, out
):  # pragma: no cover - numba
    """:func:`_through_count` at each of ``poses`` (shared out over the cores)."""
    for i in numba.prange(poses.shape[0]):
        out[i] = _through_count(
            dist, ox, oy, inv_cell, poses[i, 0], poses[i, 1], math.cos(poses[i, 2]), math.sin(poses[i, 2]), origins, pts,
            margin, depth, seg, start, ids, ix0, iy0, inv_icell, iny, inx, end_m,
        )

