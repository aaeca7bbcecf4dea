"""The likelihood field of the relocalization's search (:mod:`autonomy.localization.relocalization`):
the robust cost of scan points placed at a pose, read from the free space's distance
transform (one table look-up per point, no ray casting), over a grid of hypotheses at
once, and the pattern search that refines one hypothesis on it. numba kernels over plain
arrays, as the coarse search scores every hypothesis on the map."""

from __future__ import annotations

import math

import numba


@numba.njit(cache=True, inline="always")
def _point_cost(dist, ox, oy, inv_cell, qx, qy, robust2):  # pragma: no cover - numba
    """Robust cost min(d^2, c^2) / c^2 of one world point (1 off the grid)."""
    ny, nx = dist.shape
    j = int(math.floor((qx - ox) * inv_cell))
    k = int(math.floor((qy - oy) * inv_cell))
    if j < 0 or k < 0 or j >= nx or k >= ny:
        return 1.0
    d = dist[k, j]
    d2 = d * d
    return d2 / robust2 if d2 < robust2 else 1.0


@numba.njit(cache=True)
def _cost(dist, ox, oy, inv_cell, x, y, c, s, pts, robust2):  # pragma: no cover - numba
    acc = 0.0
    for i in range(pts.shape[0]):
        acc += _point_cost(dist, ox, oy, inv_cell, x + c * pts[i, 0] - s * pts[i, 1], y + s * pts[i, 0] + c * pts[i, 1], robust2)
    return acc / max(pts.shape[0], 1)


@numba.njit(cache=True, parallel=True)
def _grid_costs(dist, ox, oy, inv_cell, xy, rot, robust2, out):  # pragma: no cover - numba
    """out[h, k]: mean robust cost of the points pre-rotated by heading k (rot[k]) at
    position xy[h] (a translation only: the rotation is shared by all positions). The
    positions are shared out over the cores (each writes its own rows)."""
    n = rot.shape[1]
    for h in numba.prange(xy.shape[0]):
        x, y = xy[h, 0], xy[h, 1]
        for k in range(rot.shape[0]):
            acc = 0.0
            for i in range(n):
                acc += _point_cost(dist, ox, oy, inv_cell, x + rot[k, i, 0], y + rot[k, i, 1], robust2)
            out[h, k] = acc / max(n, 1)



@numba.njit(cache=True)
def _refine(dist, ox, oy, inv_cell, pose, pts, robust2, step_m, step_rad, levels):  # pragma: no cover - numba
    """Coarse-to-fine pattern search around ``pose``: at each level try the 26 neighbours
    (+-step in x, y, theta), move to the best while it improves, then halve the steps."""
    best = pose.copy()
    bc = _cost(dist, ox, oy, inv_cell, best[0], best[1], math.cos(best[2]), math.sin(best[2]), pts, robust2)
    sm, sr = step_m, step_rad
    for _ in range(levels):
        for _it in range(8):
            improved = False
            cx, cy, ct = best[0], best[1], best[2]
            for a in range(-1, 2):
                for b in range(-1, 2):
                    for g in range(-1, 2):
                        if a == 0 and b == 0 and g == 0:
                            continue
                        x, y, t = cx + a * sm, cy + b * sm, ct + g * sr
                        cst = _cost(dist, ox, oy, inv_cell, x, y, math.cos(t), math.sin(t), pts, robust2)
                        if cst < bc - 1e-12:
                            bc = cst
                            best[0], best[1], best[2] = x, y, t
                            improved = True
            if not improved:
                break
        sm *= 0.5
        sr *= 0.5
    return best, bc
