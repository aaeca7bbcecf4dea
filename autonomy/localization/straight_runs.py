"""Points on long straight runs: how much of a scan is wall.

A relocalization's scan (:class:`autonomy.localization.relocalization.Scan`) can hold hundreds of
points and still no wall: in the middle of an open hall the walls lie beyond the
camera's 4 m, and a look round sees pillars a hand's breadth wide and furniture the map
lacks. No place explains such a scan clearly, and pillars in rows repeat, so the search
stays undecided however long the robot looks there. Walls are long and straight; the
pillars' and furniture's faces are short. This module counts the scan's points that lie
on straight runs at least ``min_length_m`` long (ours; not from the papers).

Lines are found greedily, as in the sequential Hough transform: every remaining point
votes for ``n_theta`` line directions and ``band_m`` wide offsets, the bin with most
votes is a line, refitted to its points by least squares, its points within ``band_m``
of the fit are cut into runs wherever two
neighbours along it are more than ``gap_m`` apart (a door, a doorway, two pillars in a
row), the runs at least ``min_length_m`` long are counted, and all the line's points
leave the vote. A numba kernel over the flat point array; no per-point Python.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from autonomy.common.errors import InputError

GAP_M = 0.3
"""Neighbours along a line farther apart than this end a run: a doorway or the space
between two pillars in a row (the scan keeps one point per 5 cm cell)."""
BAND_M = 0.05
"""Points within this of a line lie on it (the scan's cell size: dead reckoning over
one turn in place drifts by about a degree)."""
N_THETA = 90
"""Line directions voted for: every 2 degrees."""
MAX_LINES = 16
"""At most this many lines are taken out of the vote."""
MIN_VOTES = 8
"""A bin with fewer votes ends the search (no run that long could be on it)."""


@numba.njit(cache=True)
def _straight_runs(pts, n_theta, band, gap, min_len, max_lines, min_votes, on_run):  # pragma: no cover - numba
    """Mark in ``on_run`` (n,) the points on runs at least ``min_len`` long (see the module)."""
    n = pts.shape[0]
    if n == 0:
        return
    cx, cy = 0.0, 0.0
    for i in range(n):
        cx += pts[i, 0]
        cy += pts[i, 1]
    cx /= n
    cy /= n
    rmax = 0.0
    for i in range(n):
        r = math.hypot(pts[i, 0] - cx, pts[i, 1] - cy)
        if r > rmax:
            rmax = r
    n_rho = int(2.0 * rmax / band) + 3
    cs = np.empty(n_theta)
    sn = np.empty(n_theta)
    for j in range(n_theta):
        cs[j] = math.cos(math.pi * j / n_theta)
        sn[j] = math.sin(math.pi * j / n_theta)
    left = np.ones(n, dtype=np.bool_)
    votes = np.zeros((n_theta, n_rho), dtype=np.int32)
    for i in range(n):
        for j in range(n_theta):
            votes[j, int((rmax + (pts[i, 0] - cx) * cs[j] + (pts[i, 1] - cy) * sn[j]) / band)] += 1
    idx = np.empty(n, dtype=np.int64)
    along = np.empty(n)
    for _ in range(max_lines):
        best, bj, bk = 0, 0, 0
        for j in range(n_theta):
            for k in range(n_rho):
                if votes[j, k] > best:
                    best, bj, bk = votes[j, k], j, k
        if best < min_votes:
            return
        # The bin's line is up to a degree and half a bin off the points' own: fit the
        # line to the bin's points (least squares, the covariance's principal axis), then
        # take every point within band of the fit, the ends of a long wall included.
        rho = (bk + 0.5) * band - rmax
        nx, ny, off = cs[bj], sn[bj], rho
        for _fit in range(2):
            sx, sy, k = 0.0, 0.0, 0
            for i in range(n):
                if left[i] and abs((pts[i, 0] - cx) * nx + (pts[i, 1] - cy) * ny - off) <= band:
                    sx += pts[i, 0] - cx
                    sy += pts[i, 1] - cy
                    k += 1
            if k < 2:
                break
            mx, my = sx / k, sy / k
            sxx, syy, sxy = 0.0, 0.0, 0.0
            for i in range(n):
                if left[i] and abs((pts[i, 0] - cx) * nx + (pts[i, 1] - cy) * ny - off) <= band:
                    dx, dy = pts[i, 0] - cx - mx, pts[i, 1] - cy - my
                    sxx += dx * dx
                    syy += dy * dy
                    sxy += dx * dy
            t = 0.5 * math.atan2(2.0 * sxy, sxx - syy)  # direction of the principal axis
            nx, ny = -math.sin(t), math.cos(t)
            off = mx * nx + my * ny
        m = 0
        for attempt in range(2):
            if attempt == 1:
                if m > 0:
                    break
                nx, ny, off = cs[bj], sn[bj], rho  # the fit left every point: the bin's own line
            for i in range(n):
                if left[i] and abs((pts[i, 0] - cx) * nx + (pts[i, 1] - cy) * ny - off) <= band:
                    idx[m] = i
                    along[m] = -(pts[i, 0] - cx) * ny + (pts[i, 1] - cy) * nx
                    m += 1
        order = np.argsort(along[:m])
        a = 0
        for b in range(1, m + 1):
            if b == m or along[order[b]] - along[order[b - 1]] > gap:
                if along[order[b - 1]] - along[order[a]] >= min_len:
                    for q in range(a, b):
                        on_run[idx[order[q]]] = True
                a = b
        for q in range(m):
            i = idx[q]
            left[i] = False
            for j in range(n_theta):
                votes[j, int((rmax + (pts[i, 0] - cx) * cs[j] + (pts[i, 1] - cy) * sn[j]) / band)] -= 1


def on_straight_runs(points: np.ndarray, min_length_m: float, gap_m: float = GAP_M, band_m: float = BAND_M) -> np.ndarray:
    """(n,) bool: which of the (n, 2) ``points`` lie on straight runs at least
    ``min_length_m`` long (within ``band_m`` of one line, no two neighbours along it more
    than ``gap_m`` apart)."""
    for name, v in (("min_length_m", min_length_m), ("gap_m", gap_m), ("band_m", band_m)):
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"on_straight_runs: {name} must be a finite number > 0, got {v!r}")
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2))
    if not np.isfinite(pts).all():
        raise InputError("on_straight_runs: points must be finite")
    out = np.zeros(len(pts), dtype=np.bool_)
    if len(pts):
        _straight_runs(pts, N_THETA, float(band_m), float(gap_m), float(min_length_m), MAX_LINES, MIN_VOTES, out)
    return out
