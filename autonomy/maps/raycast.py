"""Analytic ray casting on a vector map: scene lines and the visibility grid (BV2012, Sec. IV-A).

:func:`scene_lines` is Algorithm 2 ("AnalyticRayCast"): from a location x it returns the
*scene lines* L, the non-intersecting, non-occluded pieces of the map's wall segments
that x sees, each tagged with the index of the wall it came from.

TrimOcclusion(x, l1, l2) (Fig. 3) is computed exactly: the part of l1 that l2 hides from
x is l1's intersection with l2's *shadow*, the convex region inside the wedge from x
through l2's end points and beyond the line of l2. Clipping l1's parameter interval
[0, 1] against those three half-planes (each affine in the parameter) gives one occluded
interval; what is left of l1 is 0, 1 or 2 pieces, which covers the four cases of Fig. 3
(not occluded; fully occluded; partly occluded, with a second visible piece; l1 crossing
l2). A second piece of a line under test goes back on the work list; a second piece of an
existing scene line, cut by a newly accepted line, goes into the scene list.

Readings and tolerances (the paper gives none):

- Walls seen edge-on (x on the wall's line, zero angular width) are neither visible nor
  occluders; so are walls through x itself.
- A point only counts as occluded when it lies more than ``1e-9`` m beyond the occluder's
  line, so walls meeting at a corner or a T-junction, and collinear pieces of one wall,
  do not hide each other's shared end points. Collinear *overlapping* walls are the one
  exception: the later one loses the overlap, so scene lines never overlap.
- Occluded intervals and pieces shorter than ``1e-6`` m are ignored / dropped.
- Speed-ups that do not change the result (Algorithm 2 trims a line by the union of the
  shadows, whatever the order): candidates are taken roughly nearest first (one
  counting-sort pass), so near walls hide far ones early; an angular depth buffer (256
  pseudo-angle bins, each holding a distance within which every ray of the bin hits an
  accepted wall) drops walls lying wholly behind without TrimOcclusion calls; and the
  scene lines are linked into those bins, so a line is only trimmed against the scene
  lines that share its angular range.

:class:`VisibilityGrid` stores, per cell of a regular grid, the walls that can be seen
from some point of the cell within ``max_range_m`` (conservatively: every wall whose
distance to the cell's box is at most the range), so a query only looks at a few hundred
walls of a 10,000-wall map. :class:`SceneQuery` bundles a map and its grid; its scene lines
are clipped to the disk of radius ``max_range_m`` around x, which makes them identical to
the clipped scene lines of the whole map. :func:`load_or_build` caches a grid on disk as
``<map file>.visgrid.npz`` (or in ``~/.cache/depthnav``), keyed by a hash of the walls and
the config.

:func:`ray_hit` / :func:`rays_hit` intersect rays with a set of lines (e.g. scene lines).
"""

from __future__ import annotations

import hashlib
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

from autonomy.common.cache import cache_paths
from autonomy.common.errors import InputError
from autonomy.common.files import atomic_write
from autonomy.maps.vectormap import VectorMap

__all__ = [
    "scene_lines",
    "ray_hit",
    "rays_hit",
    "VisibilityGridConfig",
    "VisibilityGrid",
    "SceneQuery",
    "load_or_build",
    "benchmark_scene_lines",
    "MIN_PIECE_M",
]

MIN_PIECE_M = 1e-6
"""Scene-line pieces (and occluded intervals) shorter than this many metres are dropped."""
_BEYOND_TOL_M = 1e-9
"""A point must lie this far beyond an occluder's line to be occluded by it."""
_EDGE_ON_SIN = 1e-12
"""Walls whose angular width seen from x has a sine below this are edge-on (invisible)."""
_N_BINS = 256
"""Pseudo-angle bins of the depth buffer used to reject hidden walls early."""
_GRID_VERSION = 2
"""Bumped whenever the cache file layout or the candidate rule changes."""


# --------------------------------------------------------------------------- small kernels


@numba.njit(cache=True, inline="always")
def _pseudo_angle(x: float, y: float) -> float:
    """A number in [0, 4) that grows with atan2(y, x) from -pi (the "diamond angle": no
    trigonometry); opposite directions are 2 apart. (0, 0) gives 0."""
    a = abs(x) + abs(y)
    if a == 0.0:
        return 0.0
    p = y / a
    return p + 1.0 if x >= 0.0 else 3.0 - p


@numba.njit(cache=True, inline="always")
def _ang_overlap(a0: float, a1: float, b0: float, b1: float) -> bool:
    """Whether pseudo-angle intervals [a0, a1] and [b0, b1] (a0, b0 in [0, 4)) meet on the circle."""
    d = b0 - a0
    if d < 0.0:
        d += 4.0
    eps = 1e-12
    return d <= (a1 - a0) + eps or d + (b1 - b0) >= 4.0 - eps


@numba.njit(cache=True, inline="always")
def _clip(h0: float, h1: float, lo: float, hi: float) -> tuple[float, float]:
    """Clip [lo, hi] of s to the half-plane h(s) = h0 + s (h1 - h0) >= 0 (empty: lo > hi)."""
    if h0 < 0.0:
        if h1 < 0.0:
            return 1.0, 0.0
        t = h0 / (h0 - h1)
        if t > lo:
            lo = t
    elif h1 < 0.0:
        t = h0 / (h0 - h1)
        if t < hi:
            hi = t
    return lo, hi


@numba.njit(cache=True)
def _trim_interval(
    ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float, dy: float
) -> tuple[float, float]:
    """TrimOcclusion core: the parameter interval [lo, hi] of l1 = A + s (B - A) hidden by
    l2 = C -> D (counter-clockwise seen from the origin x), or lo > hi when none.

    Shadow of l2 = {P : cross(C, P) >= 0, cross(P, D) >= 0, P beyond the line CD}: the
    three half-planes are each affine in s, so clipping [0, 1] against them in turn gives
    the hidden interval.
    """
    # wedge side through C
    lo, hi = _clip(cx * ay - cy * ax, cx * by - cy * bx, 0.0, 1.0)
    # wedge side through D
    lo, hi = _clip(ax * dy - ay * dx, bx * dy - by * dx, lo, hi)
    if lo >= hi:
        return 1.0, 0.0
    # beyond the line of l2: -cross(D - C, P - C) >= tol * |D - C|
    ex = dx - cx
    ey = dy - cy
    tol = _BEYOND_TOL_M * math.sqrt(ex * ex + ey * ey)
    g0 = -(ex * (ay - cy) - ey * (ax - cx))
    g1 = -(ex * (by - cy) - ey * (bx - cx))
    if abs(g0) <= tol and abs(g1) <= tol:
        # l1 lies on the line of l2: the overlap is hidden (collinear duplicates).
        return lo, hi
    return _clip(g0 - tol, g1 - tol, lo, hi)


@numba.njit(cache=True, inline="always")
def _seg_dist_origin(ax: float, ay: float, bx: float, by: float) -> float:
    """Distance from the origin to segment A-B."""
    ex = bx - ax
    ey = by - ay
    l2 = ex * ex + ey * ey
    t = 0.0
    if l2 > 0.0:
        t = -(ax * ex + ay * ey) / l2
        if t < 0.0:
            t = 0.0
        elif t > 1.0:
            t = 1.0
    px = ax + t * ex
    py = ay + t * ey
    return math.sqrt(px * px + py * py)


# --------------------------------------------------------------------------- Algorithm 2


# Piece records (float rows): end points A, B relative to x (counter-clockwise seen from
# x), pseudo-angle span [a0, a1] (a0 in [0, 4), a1 - a0 < 2), distance range [dmin, dmax].
_A0, _A1, _DMIN, _DMAX = 4, 5, 6, 7


@numba.njit(cache=True)
def _set_piece(r: np.ndarray, ax: float, ay: float, bx: float, by: float) -> None:
    """Write a piece's end points, pseudo-angle span and distance range into row ``r``."""
    r[0] = ax
    r[1] = ay
    r[2] = bx
    r[3] = by
    a0 = _pseudo_angle(ax, ay)
    a1 = _pseudo_angle(bx, by)
    if a1 < a0:
        a1 += 4.0
    r[4] = a0
    r[5] = a1
    r[6] = _seg_dist_origin(ax, ay, bx, by)
    r[7] = math.sqrt(max(ax * ax + ay * ay, bx * bx + by * by))


@numba.njit(cache=True)
def _prepare(
    segments: np.ndarray, cand: np.ndarray, x: float, y: float, max_range: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Candidates relative to (x, y), clipped to the disk, oriented counter-clockwise.

    Drops walls outside the disk, shorter than the minimum piece, and seen edge-on.
    Returns piece records, source indices, whether each was flipped, and their count.
    """
    n = cand.shape[0]
    cs = np.empty((n, 8))
    csrc = np.empty(n, np.int64)
    cflip = np.empty(n, np.bool_)
    r2 = max_range * max_range
    clip = max_range < np.inf
    m = 0
    for k in range(n):
        i = cand[k]
        ax = segments[i, 0] - x
        ay = segments[i, 1] - y
        bx = segments[i, 2] - x
        by = segments[i, 3] - y
        ex = bx - ax
        ey = by - ay
        ll = ex * ex + ey * ey
        if ll <= MIN_PIECE_M * MIN_PIECE_M:
            continue
        qa = ax * ax + ay * ay
        qb = bx * bx + by * by
        if clip and (qa > r2 or qb > r2):
            # keep the part with |A + s E|^2 <= r^2
            bh = ax * ex + ay * ey
            disc = bh * bh - ll * (qa - r2)
            if disc <= 0.0:
                continue
            sq = math.sqrt(disc)
            s0 = max((-bh - sq) / ll, 0.0)
            s1 = min((-bh + sq) / ll, 1.0)
            if (s1 - s0) * math.sqrt(ll) <= MIN_PIECE_M:
                continue
            nax = ax + s0 * ex
            nay = ay + s0 * ey
            bx = ax + s1 * ex
            by = ay + s1 * ey
            ax = nax
            ay = nay
            qa = ax * ax + ay * ay
            qb = bx * bx + by * by
        c = ax * by - ay * bx
        if c * c <= (_EDGE_ON_SIN * _EDGE_ON_SIN) * qa * qb:
            continue  # seen edge-on, or through x
        if c > 0.0:
            _set_piece(cs[m], ax, ay, bx, by)
            cflip[m] = False
        else:
            _set_piece(cs[m], bx, by, ax, ay)
            cflip[m] = True
        csrc[m] = i
        m += 1
    return cs, csrc, cflip, m


@numba.njit(cache=True)
def _nearest_first(cs: np.ndarray, m: int) -> np.ndarray:
    """Indices of the first ``m`` pieces roughly by ascending ``dmin``: one counting-sort
    pass (2 m buckets), O(m) and deterministic; the order only affects speed."""
    order = np.empty(m, np.int64)
    if m == 0:
        return order
    kmax = 0.0
    for i in range(m):
        if cs[i, _DMIN] > kmax:
            kmax = cs[i, _DMIN]
    nbk = 2 * m
    scale = (nbk - 1) / kmax if kmax > 0.0 else 0.0
    cnt = np.zeros(nbk + 1, np.int64)
    bk = np.empty(m, np.int64)
    for i in range(m):
        b = int(cs[i, _DMIN] * scale)
        bk[i] = b
        cnt[b + 1] += 1
    for b in range(nbk):
        cnt[b + 1] += cnt[b]
    for i in range(m):
        b = bk[i]
        order[cnt[b]] = i
        cnt[b] += 1
    return order


@numba.njit(cache=True, inline="always")
def _register(head: np.ndarray, reg: np.ndarray, nreg: int, j: int, a0: float, a1: float, bw: float) -> int:
    """Link scene piece ``j`` into the lists of the pseudo-angle bins it spans; returns the
    new registration count, or -1 when ``reg`` is full."""
    nb_ = head.shape[0]
    b0 = int(a0 / bw)
    b1 = int(a1 / bw)
    if nreg + (b1 - b0 + 1) > reg.shape[0]:
        return -1
    for b in range(b0, b1 + 1):
        bb = b % nb_
        reg[nreg, 0] = j
        reg[nreg, 1] = head[bb]
        head[bb] = nreg
        nreg += 1
    return nreg


@numba.njit(cache=True, inline="always")
def _copy_row(dst: np.ndarray, i: int, src: np.ndarray, k: int) -> None:
    for c in range(8):
        dst[i, c] = src[k, c]


@numba.njit(cache=True)
def _cast(
    cs: np.ndarray,
    csrc: np.ndarray,
    cflip: np.ndarray,
    order: np.ndarray,
    scap: int,
    wcap: int,
    rcap: int,
) -> tuple[bool, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """Algorithm 2 proper over the prepared pieces ``cs[order]``, with fixed capacities
    (so no array is reallocated in the loop: numba is much faster that way).

    Returns (ok, S, source, flipped, alive, ns); ``ok`` False means a capacity ran out.
    """
    m = order.shape[0]
    nb_ = _N_BINS
    bw = 4.0 / nb_
    # depth buffer: every ray in bin b hits a wall within full[b]
    full = np.full(nb_, np.inf)
    lend = np.zeros(nb_)  # bin covered from its start up to this offset ...
    ldep = np.full(nb_, np.inf)  # ... by a line no farther than this
    rsta = np.full(nb_, bw)  # bin covered from this offset to its end ...
    rdep = np.full(nb_, np.inf)  # ... by a line no farther than this
    # scene list S, with per-bin linked lists of the pieces spanning each bin
    S = np.empty((scap, 8))
    ssrc = np.empty(scap, np.int64)
    sflip = np.empty(scap, np.bool_)
    salive = np.empty(scap, np.bool_)
    stamp = np.empty(scap, np.int64)
    ns = 0
    head = np.full(nb_, -1, np.int64)
    reg = np.empty((rcap, 2), np.int64)  # (piece, next registration in the bin)
    nreg = 0
    # work stack of second pieces (Fig. 3 cases 3 and 4)
    W = np.empty((wcap, 8))
    wsrc = np.empty(wcap, np.int64)
    wflip = np.empty(wcap, np.bool_)
    nw = 0
    cur = np.empty((1, 8))
    visit = 0
    k = 0
    while True:
        if nw > 0:
            nw -= 1
            _copy_row(cur, 0, W, nw)
            src = wsrc[nw]
            flip = wflip[nw]
        elif k < m:
            ci = order[k]
            k += 1
            # depth-buffer rejection: every bin the line touches is closed nearer than it
            b0 = int(cs[ci, _A0] / bw)
            b1 = int(cs[ci, _A1] / bw)
            dm = cs[ci, _DMIN] - 1e-9
            hidden = True
            for b in range(b0, b1 + 1):
                if full[b % nb_] >= dm:
                    hidden = False
                    break
            if hidden:
                continue
            _copy_row(cur, 0, cs, ci)
            src = csrc[ci]
            flip = cflip[ci]
        else:
            break
        c = cur[0]

        # -- Algorithm 2 lines 5-7: TrimOcclusion(x, l_i, l_j, L) for the scene lines l_j
        visit += 1
        alive = True
        b0 = int(c[_A0] / bw)
        b1 = int(c[_A1] / bw)
        for b in range(b0, b1 + 1):
            r = head[b % nb_]
            while r >= 0:
                j = reg[r, 0]
                r = reg[r, 1]
                if stamp[j] == visit or not salive[j]:
                    continue
                stamp[j] = visit
                if S[j, _DMIN] >= c[_DMAX]:
                    continue
                if not _ang_overlap(c[_A0], c[_A1], S[j, _A0], S[j, _A1]):
                    continue
                ax = c[0]
                ay = c[1]
                bx = c[2]
                by = c[3]
                lo, hi = _trim_interval(ax, ay, bx, by, S[j, 0], S[j, 1], S[j, 2], S[j, 3])
                if lo >= hi:
                    continue
                ex = bx - ax
                ey = by - ay
                ln = math.sqrt(ex * ex + ey * ey)
                if (hi - lo) * ln < MIN_PIECE_M:
                    continue
                keep_l = lo * ln >= MIN_PIECE_M
                keep_r = (1.0 - hi) * ln >= MIN_PIECE_M
                if keep_l and keep_r:  # second piece back on the work list
                    if nw == wcap:
                        return False, S, ssrc, sflip, salive, 0
                    _set_piece(W[nw], ax + hi * ex, ay + hi * ey, bx, by)
                    wsrc[nw] = src
                    wflip[nw] = flip
                    nw += 1
                    _set_piece(c, ax, ay, ax + lo * ex, ay + lo * ey)
                elif keep_l:
                    _set_piece(c, ax, ay, ax + lo * ex, ay + lo * ey)
                elif keep_r:
                    _set_piece(c, ax + hi * ex, ay + hi * ey, bx, by)
                else:
                    alive = False
                    break
            if not alive:
                break
        if not alive:
            continue

        # -- lines 9-11: TrimOcclusion(x, l_j, l_i, L) for the scene lines l_j
        visit += 1
        b0 = int(c[_A0] / bw)
        b1 = int(c[_A1] / bw)
        for b in range(b0, b1 + 1):
            r = head[b % nb_]
            while r >= 0:
                j = reg[r, 0]
                r = reg[r, 1]
                if stamp[j] == visit or not salive[j]:
                    continue
                stamp[j] = visit
                if S[j, _DMAX] <= c[_DMIN]:
                    continue
                if not _ang_overlap(c[_A0], c[_A1], S[j, _A0], S[j, _A1]):
                    continue
                ax = S[j, 0]
                ay = S[j, 1]
                bx = S[j, 2]
                by = S[j, 3]
                lo, hi = _trim_interval(ax, ay, bx, by, c[0], c[1], c[2], c[3])
                if lo >= hi:
                    continue
                ex = bx - ax
                ey = by - ay
                ln = math.sqrt(ex * ex + ey * ey)
                if (hi - lo) * ln < MIN_PIECE_M:
                    continue
                keep_l = lo * ln >= MIN_PIECE_M
                keep_r = (1.0 - hi) * ln >= MIN_PIECE_M
                if keep_l and keep_r:  # second piece into the scene list
                    if ns == scap:
                        return False, S, ssrc, sflip, salive, 0
                    _set_piece(S[ns], ax + hi * ex, ay + hi * ey, bx, by)
                    ssrc[ns] = ssrc[j]
                    sflip[ns] = sflip[j]
                    salive[ns] = True
                    stamp[ns] = visit
                    nreg = _register(head, reg, nreg, ns, S[ns, _A0], S[ns, _A1], bw)
                    if nreg < 0:
                        return False, S, ssrc, sflip, salive, 0
                    ns += 1
                    _set_piece(S[j], ax, ay, ax + lo * ex, ay + lo * ey)
                elif keep_l:
                    _set_piece(S[j], ax, ay, ax + lo * ex, ay + lo * ey)
                elif keep_r:
                    _set_piece(S[j], ax + hi * ex, ay + hi * ey, bx, by)
                else:
                    salive[j] = False

        # -- line 12: add the line to the scene list
        if ns == scap:
            return False, S, ssrc, sflip, salive, 0
        _copy_row(S, ns, cur, 0)
        ssrc[ns] = src
        sflip[ns] = flip
        salive[ns] = True
        stamp[ns] = visit
        nreg = _register(head, reg, nreg, ns, c[_A0], c[_A1], bw)
        if nreg < 0:
            return False, S, ssrc, sflip, salive, 0
        ns += 1

        # depth buffer: bins inside the line's span are closed at its far distance; an
        # end bin is closed once lines cover it from both of its sides
        a0 = c[_A0]
        a1 = c[_A1]
        dmax = c[_DMAX]
        if b1 > b0:
            for b in range(b0 + 1, b1):
                bb = b % nb_
                if dmax < full[bb]:
                    full[bb] = dmax
            bb = b1 % nb_
            off = a1 - b1 * bw
            if off > lend[bb]:
                lend[bb] = off
                ldep[bb] = dmax
                if lend[bb] >= rsta[bb] - 1e-12:
                    d = max(ldep[bb], rdep[bb])
                    if d < full[bb]:
                        full[bb] = d
            bb = b0 % nb_
            off = a0 - b0 * bw
            if off < rsta[bb]:
                rsta[bb] = off
                rdep[bb] = dmax
                if lend[bb] >= rsta[bb] - 1e-12:
                    d = max(ldep[bb], rdep[bb])
                    if d < full[bb]:
                        full[bb] = d
    return True, S, ssrc, sflip, salive, ns


@numba.njit(cache=True)
def _scene_lines_kernel(
    segments: np.ndarray, cand: np.ndarray, x: float, y: float, max_range: float
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 2 over ``segments[cand]`` from (x, y), clipped to the disk of ``max_range``."""
    cs, csrc, cflip, m = _prepare(segments, cand, x, y, max_range)
    order = _nearest_first(cs, m)
    scap = 2 * m + 32
    wcap = m + 16
    rcap = 2 * _N_BINS + 8 * m + 64
    while True:
        ok, S, ssrc, sflip, salive, ns = _cast(cs, csrc, cflip, order, scap, wcap, rcap)
        if ok:
            break
        scap *= 2
        wcap *= 2
        rcap *= 2
    # output: alive scene lines in world coordinates, in their walls' orientation
    cnt = 0
    for j in range(ns):
        if salive[j]:
            cnt += 1
    lines = np.empty((cnt, 4))
    src_out = np.empty(cnt, np.int64)
    o = 0
    for j in range(ns):
        if not salive[j]:
            continue
        if sflip[j]:
            lines[o, 0] = S[j, 2] + x
            lines[o, 1] = S[j, 3] + y
            lines[o, 2] = S[j, 0] + x
            lines[o, 3] = S[j, 1] + y
        else:
            lines[o, 0] = S[j, 0] + x
            lines[o, 1] = S[j, 1] + y
            lines[o, 2] = S[j, 2] + x
            lines[o, 3] = S[j, 3] + y
        src_out[o] = ssrc[j]
        o += 1
    return lines, src_out


def _check_segments(segments: np.ndarray) -> np.ndarray:
    seg = np.ascontiguousarray(segments, dtype=np.float64)
    if seg.ndim != 2 or seg.shape[1] != 4:
        raise InputError(f"segments must have shape (N, 4) [x1, y1, x2, y2], got {seg.shape}")
    return seg


def scene_lines(
    segments: np.ndarray,
    x: float,
    y: float,
    candidates: np.ndarray | None = None,
    *,
    max_range_m: float = math.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Analytic ray cast (BV2012, Algorithm 2) from (x, y).

    Returns ``(lines, source)``: the (M, 4) visible, non-intersecting, non-occluded pieces
    ``x1, y1, x2, y2`` of the map segments (each a sub-segment of, and oriented like, its
    wall) and the (M,) int64 index into ``segments`` each came from. ``candidates``
    restricts the input to those segment indices (None: all). With a finite
    ``max_range_m`` the pieces are clipped to the disk of that radius around (x, y).
    """
    seg = _check_segments(segments)
    if not (math.isfinite(x) and math.isfinite(y)):
        raise InputError(f"scene_lines: location must be finite, got ({x}, {y})")
    if not max_range_m > 0:
        raise InputError(f"scene_lines: max_range_m must be positive, got {max_range_m}")
    if candidates is None:
        cand = np.arange(seg.shape[0], dtype=np.int64)
    else:
        cand = np.ascontiguousarray(candidates)
        if cand.ndim != 1 or (cand.size and not np.issubdtype(cand.dtype, np.integer)):
            raise InputError(f"scene_lines: candidates must be a 1D integer array, got {cand.dtype} {cand.shape}")
        cand = cand.astype(np.int64, copy=False)
        if cand.size and (cand.min() < 0 or cand.max() >= seg.shape[0]):
            raise InputError(f"scene_lines: candidate indices must be in [0, {seg.shape[0]})")
    return _scene_lines_kernel(seg, cand, float(x), float(y), float(max_range_m))


# --------------------------------------------------------------------------- ray hits


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


# --------------------------------------------------------------------------- visibility grid


@dataclass(frozen=True)
class VisibilityGridConfig:
    """Visibility grid parameters (ours: the paper precomputes visibility without details)."""

    cell_m: float = 0.5
    """Cell size in metres."""
    max_range_m: float = 8.0
    """Walls farther than this from every point of a cell are not candidates (sensor range)."""

    def __post_init__(self) -> None:
        for name in ("cell_m", "max_range_m"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise InputError(f"VisibilityGridConfig.{name}: expected a positive number, got {v!r}")


@numba.njit(cache=True, inline="always")
def _pt_seg_d2(px: float, py: float, ax: float, ay: float, bx: float, by: float) -> float:
    ex = bx - ax
    ey = by - ay
    l2 = ex * ex + ey * ey
    t = 0.0
    if l2 > 0.0:
        t = ((px - ax) * ex + (py - ay) * ey) / l2
        if t < 0.0:
            t = 0.0
        elif t > 1.0:
            t = 1.0
    qx = ax + t * ex - px
    qy = ay + t * ey - py
    return qx * qx + qy * qy


@numba.njit(cache=True, inline="always")
def _pt_box_d2(px: float, py: float, x0: float, y0: float, x1: float, y1: float) -> float:
    dx = 0.0
    if px < x0:
        dx = x0 - px
    elif px > x1:
        dx = px - x1
    dy = 0.0
    if py < y0:
        dy = y0 - py
    elif py > y1:
        dy = py - y1
    return dx * dx + dy * dy


@numba.njit(cache=True)
def _seg_box_d2(
    ax: float, ay: float, bx: float, by: float, x0: float, y0: float, x1: float, y1: float
) -> float:
    """Squared distance between segment A-B and the box [x0, x1] x [y0, y1]."""
    # Liang-Barsky: does the segment meet the box?
    ex = bx - ax
    ey = by - ay
    lo = 0.0
    hi = 1.0
    meets = True
    for p, q in ((-ex, ax - x0), (ex, x1 - ax), (-ey, ay - y0), (ey, y1 - ay)):
        if p == 0.0:
            if q < 0.0:
                meets = False
                break
        else:
            t = q / p
            if p < 0.0:
                if t > lo:
                    lo = t
            elif t < hi:
                hi = t
            if lo > hi:
                meets = False
                break
    if meets:
        return 0.0
    d = min(_pt_box_d2(ax, ay, x0, y0, x1, y1), _pt_box_d2(bx, by, x0, y0, x1, y1))
    d = min(d, _pt_seg_d2(x0, y0, ax, ay, bx, by))
    d = min(d, _pt_seg_d2(x1, y0, ax, ay, bx, by))
    d = min(d, _pt_seg_d2(x0, y1, ax, ay, bx, by))
    d = min(d, _pt_seg_d2(x1, y1, ax, ay, bx, by))
    return d


@numba.njit(cache=True)
def _grid_pass(
    segments: np.ndarray,
    x0: float,
    y0: float,
    cell: float,
    nx: int,
    ny: int,
    rng: float,
    counts: np.ndarray,
    indices: np.ndarray,
    fill: bool,
) -> None:
    """One pass over the segments: count (``fill`` False) or store (True) cell members."""
    r2 = rng * rng
    for i in range(segments.shape[0]):
        ax = segments[i, 0]
        ay = segments[i, 1]
        bx = segments[i, 2]
        by = segments[i, 3]
        ix0 = max(0, int(math.floor((min(ax, bx) - rng - x0) / cell)))
        ix1 = min(nx - 1, int(math.floor((max(ax, bx) + rng - x0) / cell)))
        iy0 = max(0, int(math.floor((min(ay, by) - rng - y0) / cell)))
        iy1 = min(ny - 1, int(math.floor((max(ay, by) + rng - y0) / cell)))
        for iy in range(iy0, iy1 + 1):
            cy0 = y0 + iy * cell
            for ix in range(ix0, ix1 + 1):
                cx0 = x0 + ix * cell
                if _seg_box_d2(ax, ay, bx, by, cx0, cy0, cx0 + cell, cy0 + cell) <= r2:
                    c = iy * nx + ix
                    if fill:
                        indices[counts[c]] = i
                    counts[c] += 1


@numba.njit(cache=True)
def _build_grid_kernel(
    segments: np.ndarray, x0: float, y0: float, cell: float, nx: int, ny: int, rng: float
) -> tuple[np.ndarray, np.ndarray]:
    """CSR (offsets, indices) of the segments within ``rng`` of each cell's box."""
    ncell = nx * ny
    counts = np.zeros(ncell, np.int64)
    indices = np.empty(0, np.int32)
    _grid_pass(segments, x0, y0, cell, nx, ny, rng, counts, indices, False)
    offsets = np.empty(ncell + 1, np.int64)
    offsets[0] = 0
    for c in range(ncell):
        offsets[c + 1] = offsets[c] + counts[c]
    indices = np.empty(offsets[ncell], np.int32)
    fillpos = offsets[:ncell].copy()
    _grid_pass(segments, x0, y0, cell, nx, ny, rng, fillpos, indices, True)
    return offsets, indices


@numba.njit(cache=True)
def _near_point(segments: np.ndarray, x: float, y: float, rng: float) -> np.ndarray:
    """Indices of the segments within ``rng`` of (x, y) (grid fallback)."""
    r2 = rng * rng
    out = np.empty(segments.shape[0], np.int32)
    k = 0
    for i in range(segments.shape[0]):
        if _pt_seg_d2(x, y, segments[i, 0], segments[i, 1], segments[i, 2], segments[i, 3]) <= r2:
            out[k] = i
            k += 1
    return out[:k]


@numba.njit(cache=True)
def _query_kernel(
    segments: np.ndarray,
    offsets: np.ndarray,
    indices: np.ndarray,
    x0: float,
    y0: float,
    cell: float,
    nx: int,
    ny: int,
    rng: float,
    x: float,
    y: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Grid lookup + Algorithm 2 clipped to ``rng`` in one call (no Python in between)."""
    fx = (x - x0) / cell
    fy = (y - y0) / cell
    if 0.0 <= fx <= nx and 0.0 <= fy <= ny:
        ix = min(int(fx), nx - 1)
        iy = min(int(fy), ny - 1)
        c = iy * nx + ix
        cand = indices[offsets[c] : offsets[c + 1]]
    else:
        cand = _near_point(segments, x, y, rng)
    return _scene_lines_kernel(segments, cand.astype(np.int64), x, y, rng)


def _segments_hash(segments: np.ndarray) -> str:
    seg = np.ascontiguousarray(segments, dtype=np.float64)
    h = hashlib.sha256()
    h.update(str(seg.shape).encode())
    h.update(seg.tobytes())
    return h.hexdigest()


def _grid_key(segments: np.ndarray, cfg: VisibilityGridConfig) -> str:
    h = hashlib.sha256()
    h.update(f"depthnav-visgrid-v{_GRID_VERSION}|{cfg.cell_m!r}|{cfg.max_range_m!r}|".encode())
    h.update(_segments_hash(segments).encode())
    return h.hexdigest()


@dataclass(frozen=True, eq=False)
class VisibilityGrid:
    """Per-cell candidate walls for :func:`scene_lines`, in CSR form.

    Cell ``(ix, iy)`` covers ``[x0 + ix c, x0 + (ix + 1) c) x [y0 + iy c, ...)`` and has flat
    index ``iy * nx + ix``; its candidates are ``indices[offsets[k]:offsets[k + 1]]``, the
    (ascending) indices of the walls whose distance to the cell's box is at most
    ``config.max_range_m`` — every wall visible from the cell within that range.
    """

    offsets: np.ndarray
    """(nx * ny + 1,) int64 CSR offsets."""
    indices: np.ndarray
    """(nnz,) int32 segment indices."""
    origin: tuple[float, float]
    """(x0, y0): lower-left corner of cell (0, 0), metres."""
    shape: tuple[int, int]
    """(ny, nx): rows (y) and columns (x) of cells."""
    config: VisibilityGridConfig
    """Cell size and range the grid was built with."""
    segments: np.ndarray
    """(N, 4) read-only walls of the map the grid was built for (for the fallback)."""
    key: str
    """Hash of the map's segments and the config (cache key)."""

    @property
    def n_segments(self) -> int:
        """Number of walls of the map the grid was built for."""
        return int(self.segments.shape[0])

    @property
    def nx(self) -> int:
        """Cells along x."""
        return self.shape[1]

    @property
    def ny(self) -> int:
        """Cells along y."""
        return self.shape[0]

    @property
    def counts(self) -> np.ndarray:
        """(ny, nx) number of candidates per cell."""
        return np.diff(self.offsets).reshape(self.shape)

    @classmethod
    def build(cls, vm: VectorMap, cfg: VisibilityGridConfig = VisibilityGridConfig()) -> VisibilityGrid:  # noqa: B008
        """Grid over the map's extent; candidates by segment-to-cell-box distance (numba)."""
        if vm.n_segments == 0:
            raise InputError(f"vector map {vm.name!r} has no segments: no visibility grid")
        xmin, ymin, xmax, ymax = vm.extent()
        c = float(cfg.cell_m)
        nx = max(1, math.ceil((xmax - xmin) / c))
        ny = max(1, math.ceil((ymax - ymin) / c))
        if nx * ny > 50_000_000:
            raise InputError(f"visibility grid of {nx} x {ny} cells is too large; use a larger cell_m than {c}")
        offsets, indices = _build_grid_kernel(vm.segments, xmin, ymin, c, nx, ny, float(cfg.max_range_m))
        return cls(
            offsets=offsets,
            indices=indices,
            origin=(float(xmin), float(ymin)),
            shape=(int(ny), int(nx)),
            config=cfg,
            segments=vm.segments,
            key=_grid_key(vm.segments, cfg),
        )

    def cell_of(self, x: float, y: float) -> int:
        """Flat index of the cell containing (x, y), or -1 outside the grid."""
        fx = (x - self.origin[0]) / self.config.cell_m
        fy = (y - self.origin[1]) / self.config.cell_m
        if not (0.0 <= fx <= self.nx and 0.0 <= fy <= self.ny):
            return -1
        return min(int(fy), self.ny - 1) * self.nx + min(int(fx), self.nx - 1)

    def candidates(self, x: float, y: float) -> np.ndarray:
        """int64 indices of the walls that can be visible from the cell of (x, y) within range;
        outside the grid, those within ``max_range_m`` of the point itself."""
        c = self.cell_of(x, y)
        if c >= 0:
            return self.indices[self.offsets[c] : self.offsets[c + 1]].astype(np.int64)
        return _near_point(self.segments, float(x), float(y), float(self.config.max_range_m)).astype(np.int64)

    # ---- files

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the grid to ``path`` (an ``.npz``; written atomically)."""
        p = Path(path)
        arrays = {
            "version": np.array(_GRID_VERSION),
            "offsets": self.offsets,
            "indices": self.indices,
            "origin": np.array(self.origin, dtype=np.float64),
            "shape": np.array(self.shape, dtype=np.int64),
            "cell_m": np.array(self.config.cell_m, dtype=np.float64),
            "max_range_m": np.array(self.config.max_range_m, dtype=np.float64),
            "segments": self.segments,
            "key": np.array(self.key),
        }
        try:
            return atomic_write(p, lambda f: np.savez_compressed(f, **arrays))
        except OSError as e:
            raise InputError(f"{p}: cannot write visibility grid ({e.strerror or e})") from None

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> VisibilityGrid:
        """Read a grid written by :meth:`save`; a missing or malformed file is an InputError."""
        p = Path(path)
        try:
            with np.load(p, allow_pickle=False) as z:
                version = int(z["version"])
                if version != _GRID_VERSION:
                    raise InputError(f"{p}: visibility grid version {version}, expected {_GRID_VERSION}")
                offsets = np.ascontiguousarray(z["offsets"], dtype=np.int64)
                indices = np.ascontiguousarray(z["indices"], dtype=np.int32)
                origin = tuple(float(v) for v in z["origin"])
                shape = tuple(int(v) for v in z["shape"])
                cfg = VisibilityGridConfig(float(z["cell_m"]), float(z["max_range_m"]))
                seg = np.ascontiguousarray(z["segments"], dtype=np.float64)
                key = str(z["key"])
        except InputError:
            raise
        except FileNotFoundError:
            raise InputError(f"{p}: file not found") from None
        except Exception as e:  # zip, zlib, npy header, missing key ...
            raise InputError(f"{p}: not a visibility grid file ({type(e).__name__}: {e})") from None
        if len(origin) != 2 or len(shape) != 2 or min(shape) < 1:
            raise InputError(f"{p}: bad visibility grid origin/shape {origin} {shape}")
        if seg.ndim != 2 or seg.shape[1] != 4 or _grid_key(seg, cfg) != key:
            raise InputError(f"{p}: visibility grid key does not match its segments and config")
        n_seg = seg.shape[0]
        ncell = shape[0] * shape[1]
        if (
            offsets.shape != (ncell + 1,)
            or offsets[0] != 0
            or offsets[-1] != indices.shape[0]
            or np.any(np.diff(offsets) < 0)
            or (indices.size and (indices.min() < 0 or indices.max() >= n_seg))
        ):
            raise InputError(f"{p}: inconsistent visibility grid arrays")
        seg.setflags(write=False)
        return cls(offsets, indices, origin, shape, cfg, seg, key)  # type: ignore[arg-type]


def load_or_build(
    vm: VectorMap,
    map_path: str | os.PathLike[str] | None,
    cfg: VisibilityGridConfig = VisibilityGridConfig(),  # noqa: B008
) -> VisibilityGrid:
    """The grid of ``vm``, cached as ``<map file>.visgrid.npz`` (or under ``~/.cache/depthnav``
    when that directory is not writable or there is no map file).

    The cache is keyed by a hash of the segments and the config: a stale, foreign or
    corrupt cache file is rebuilt and overwritten, never an error.
    """
    key = _grid_key(vm.segments, cfg)
    paths = cache_paths(map_path, key, ".visgrid.npz")
    for p in paths:
        if not p.is_file():
            continue
        try:
            g = VisibilityGrid.load(p)
        except InputError:
            continue
        if g.key == key and g.config == cfg and np.array_equal(g.segments, vm.segments):
            return g
    g = VisibilityGrid.build(vm, cfg)
    for p in cache_paths(map_path, key, ".visgrid.npz", for_writing=True):
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            g.save(p)
            break
        except (OSError, InputError):
            continue
    return g


# --------------------------------------------------------------------------- SceneQuery


class SceneQuery:
    """A map plus its visibility grid: scene lines for any location (BV2012, Sec. IV-A).

    Scene lines are clipped to the disk of ``grid.config.max_range_m`` around the
    location; within that disk they equal :func:`scene_lines` over the whole map.
    """

    def __init__(self, vm: VectorMap, grid: VisibilityGrid | None = None) -> None:
        if grid is None:
            grid = VisibilityGrid.build(vm)
        elif grid.segments.shape != vm.segments.shape or not np.array_equal(grid.segments, vm.segments):
            raise InputError(f"visibility grid was built for another map than {vm.name!r}")
        self.vm = vm
        self.grid = grid
        self._seg = vm.segments
        self._args = (
            grid.offsets,
            grid.indices,
            float(grid.origin[0]),
            float(grid.origin[1]),
            float(grid.config.cell_m),
            int(grid.nx),
            int(grid.ny),
            float(grid.config.max_range_m),
        )

    @property
    def max_range_m(self) -> float:
        """Range the scene lines are clipped to."""
        return float(self.grid.config.max_range_m)

    def candidates(self, x: float, y: float) -> np.ndarray:
        """int64 candidate wall indices for (x, y) (see :meth:`VisibilityGrid.candidates`)."""
        return self.grid.candidates(x, y)

    def scene_lines(self, x: float, y: float) -> tuple[np.ndarray, np.ndarray]:
        """``(lines (M, 4), source (M,) int64)`` seen from (x, y), as :func:`scene_lines`."""
        return _query_kernel(self._seg, *self._args, float(x), float(y))


# --------------------------------------------------------------------------- benchmark


def _free_points(vm: VectorMap, n: int, rng: np.random.Generator, clearance_m: float = 0.3) -> np.ndarray:
    """``n`` uniform points in the map's extent at least ``clearance_m`` from every wall."""
    xmin, ymin, xmax, ymax = vm.extent()
    seg = vm.segments
    out: list[np.ndarray] = []
    have = 0
    while have < n:
        p = rng.uniform((xmin, ymin), (xmax, ymax), size=(max(64, n), 2))
        a = seg[None, :, 0:2]
        e = seg[None, :, 2:4] - a
        ok = np.ones(len(p), dtype=bool)
        for s in range(0, len(p), 64):
            q = p[s : s + 64, None, :]
            t = np.clip(((q - a) * e).sum(-1) / (e * e).sum(-1), 0.0, 1.0)
            d = np.hypot(*np.moveaxis(a + t[..., None] * e - q, -1, 0)).min(axis=1)
            ok[s : s + 64] = d >= clearance_m
        out.append(p[ok])
        have += int(ok.sum())
    return np.concatenate(out)[:n]


def benchmark_scene_lines(
    vm: VectorMap, n: int = 1000, *, seed: int = 0, grid: VisibilityGrid | None = None
) -> float:
    """Median microseconds of one :meth:`SceneQuery.scene_lines` call at ``n`` random free
    locations (>= 0.3 m from any wall) of ``vm``, grid included, JIT warmed up."""
    q = SceneQuery(vm, grid)
    pts = _free_points(vm, n, np.random.default_rng(seed))
    for p in pts[:5]:
        q.scene_lines(p[0], p[1])
    times = np.empty(len(pts))
    for i, (px, py) in enumerate(pts):
        t0 = time.perf_counter_ns()
        q.scene_lines(px, py)
        times[i] = time.perf_counter_ns() - t0
    return float(np.median(times) / 1e3)
