"""Analytic ray casting on a vector map: the scene lines of BV2012, Algorithm 2 (Sec. IV-A).

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
"""

from __future__ import annotations

import math

import numba
import numpy as np

from autonomy.common.errors import InputError
from autonomy.maps.ray_hits import _check_segments, _pseudo_angle

__all__ = ["scene_lines", "MIN_PIECE_M"]

MIN_PIECE_M = 1e-6
"""Scene-line pieces (and occluded intervals) shorter than this many metres are dropped."""
_BEYOND_TOL_M = 1e-9
"""A point must lie this far beyond an occluder's line to be occluded by it."""
_EDGE_ON_SIN = 1e-12
"""Walls whose angular width seen from x has a sine below this are edge-on (invisible)."""
_N_BINS = 256
"""Pseudo-angle bins of the depth buffer used to reject hidden walls early."""

# --------------------------------------------------------------------------- small kernels


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
