"""What the vector map loader checks in a map's wall segments, and what it does about it.

:func:`clean_segments` takes the parsed (N, 4) segments ``x1, y1, x2, y2`` of a file,
with a label for each row (its line number in a text map, ``[i] (line L)`` in a JSON
map), and returns the rows to keep plus one :class:`Finding` per problem:

- ``non_finite`` (error): a NaN or infinite coordinate.
- ``zero_length`` (dropped): both end points equal once rounded to 1e-9 m.
- ``no_segments`` (error): nothing left after dropping zero-length segments.
- ``duplicate`` (dropped, the first copy kept): the same end points as an earlier
  segment, in either direction, once rounded to 1e-9 m.
- ``extent`` (error over 5 km, which is a millimetre map, or under 0.5 m; a warning over
  500 m): the bounding box does not look like one building in metres.
- ``overlap`` (reported, left as it is): two segments on the same line (within 1 cm and
  0.5 degrees) whose extents overlap by more than 1 cm. Collinear pieces that only touch
  end to end are not an overlap.

Each finding's :attr:`Finding.message` is one line naming the file, the first
:data:`MAX_LISTED` rows and what was done. The loader in :mod:`autonomy.maps.vectormap` raises
an error finding as a :class:`~autonomy.maps.vectormap.MapFormatError` and logs the others on
the ``"depthnav.map"`` logger (:data:`LOGGER_NAME`), so they print as one line each and
can be silenced or routed with :mod:`logging`. :func:`autonomy.maps.vectormap.check_vectormap` runs the same
checks on a map already in memory. All checks are vectorised: about 10 ms for 10,000
segments.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "LOGGER_NAME",
    "Finding",
    "Cleaned",
    "clean_segments",
    "log_findings",
    "ROUND_M",
    "OVERLAP_DIST_M",
    "OVERLAP_ANGLE_DEG",
    "OVERLAP_MIN_M",
    "MAX_EXTENT_M",
    "WARN_EXTENT_M",
    "MIN_EXTENT_M",
    "MAX_LISTED",
]

LOGGER_NAME = "depthnav.map"
"""The logger the loader reports its findings on (one warning per finding)."""

ROUND_M = 1e-9
"""Coordinates are rounded to this grid (metres) before comparing end points."""
OVERLAP_DIST_M = 0.01
"""Two segments are on the same line if each is within this distance of the other's line..."""
OVERLAP_ANGLE_DEG = 0.5
"""...and their directions differ by at most this angle."""
OVERLAP_MIN_M = 0.01
"""Segments on the same line overlap if their extents share more than this length."""
MAX_EXTENT_M = 5000.0
"""A map wider or taller than this is an error (it is almost surely in millimetres)."""
WARN_EXTENT_M = 500.0
"""A map wider or taller than this (up to :data:`MAX_EXTENT_M`) is a warning."""
MIN_EXTENT_M = 0.5
"""A map whose width and height are both below this is an error."""
MAX_LISTED = 10
"""A message lists this many rows, then ``", ..."``."""

_ROUND_LIMIT = 1e6  # beyond this magnitude a coordinate is compared as it is
_CHUNK = 1 << 20  # overlap candidate pairs tested at a time


@dataclass(frozen=True, eq=False)
class Finding:
    """One problem in a map: what, where, and what was done about it."""

    check: str
    """``"non_finite"``, ``"zero_length"``, ``"no_segments"``, ``"duplicate"``, ``"extent"`` or ``"overlap"``."""
    severity: str
    """``"error"`` (the loader refuses the map) or ``"warning"`` (loaded; dropped rows said so)."""
    message: str
    """One line: the file, the first rows concerned, and what was done."""
    rows: Any = ()
    """(K,) int64, sorted: the 0-based input rows concerned (the dropped ones, the
    non-finite ones, the overlapping ones, or those holding the extreme coordinates)."""
    pairs: Any = ()
    """(P, 2) int64: for ``overlap``, the overlapping row pairs ``(i, j)``, ``i < j``, sorted."""
    line: int | None = None
    """For errors, the line number to name in the exception, when there is one."""

    def __post_init__(self) -> None:
        for name, shape in (("rows", (-1,)), ("pairs", (-1, 2))):
            a = np.array(getattr(self, name), dtype=np.int64).reshape(shape)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def __str__(self) -> str:
        return self.message


@dataclass(frozen=True)
class Cleaned:
    """What :func:`clean_segments` returns."""

    segments: np.ndarray
    """(M, 4) float64: the rows kept, in input order."""
    kept: np.ndarray
    """(M,) int64: their input row indices."""
    findings: tuple[Finding, ...]
    """Every problem found, in check order."""

    @property
    def errors(self) -> tuple[Finding, ...]:
        """The findings that make the map unusable."""
        return tuple(f for f in self.findings if f.severity == "error")

    @property
    def warnings(self) -> tuple[Finding, ...]:
        """The other findings."""
        return tuple(f for f in self.findings if f.severity != "error")


# --------------------------------------------------------------------------- messages


class _IndexLabels:
    """``labels[i]`` -> ``"[i]"`` (a map in memory has no line numbers)."""

    def __getitem__(self, i: int) -> str:
        return f"[{int(i)}]"


def _listing(items: Sequence[Any] | np.ndarray, fmt: Any) -> str:
    shown = ", ".join(fmt(x) for x in items[:MAX_LISTED])
    return shown + (", ..." if len(items) > MAX_LISTED else "")


def _metres(v: float) -> str:
    return f"{v:.1f}" if abs(v) >= 10 else f"{v:.3g}"


# --------------------------------------------------------------------------- checks


def _rounded(seg: np.ndarray) -> np.ndarray:
    """Coordinates on the ROUND_M grid; huge ones (where the grid is below a float step) as they are."""
    small = np.abs(seg) < _ROUND_LIMIT
    q = np.where(small, np.round(np.where(small, seg, 0.0) / ROUND_M) * ROUND_M, seg)
    return q + 0.0  # -0.0 -> 0.0, so the sort below sees one zero


def _canonical(q: np.ndarray) -> np.ndarray:
    """Each row with its end points in (x, y) order, so a reversed segment matches."""
    swap = (q[:, 2] < q[:, 0]) | ((q[:, 2] == q[:, 0]) & (q[:, 3] < q[:, 1]))
    c = q.copy()
    c[swap] = q[swap][:, [2, 3, 0, 1]]
    return c


def _duplicates(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(dup, first): rows equal to an earlier row, and the earliest such row for each."""
    if c.shape[0] < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.lexsort((c[:, 3], c[:, 2], c[:, 1], c[:, 0]))  # stable: equal rows keep input order
    s = c[order]
    same = (s[1:] == s[:-1]).all(axis=1)
    if not same.any():
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    start = np.r_[True, ~same]
    group_first = order[np.flatnonzero(start)][np.cumsum(start) - 1]
    k = np.flatnonzero(same) + 1
    dup = order[k]
    first = group_first[k]
    by_row = np.argsort(dup, kind="stable")
    return dup[by_row], first[by_row]


def _sorted_unique(x: np.ndarray) -> np.ndarray:
    """np.unique by sorting (numpy's hash-based unique is slow on packed pairs)."""
    x = np.sort(x)
    return x[np.r_[True, x[1:] != x[:-1]]] if x.size else x


def _overlap_pairs(seg: np.ndarray) -> np.ndarray:
    """(P, 2) row pairs ``i < j`` of segments on one line that overlap (see the module doc).

    Candidates come from grouping segments by direction (bins of about 1.1 degrees, in two
    grids half a bin apart so that any two directions within the tolerance share a bin in
    one of them) and, inside a group, by the perpendicular coordinate in the group's frame
    (bins of 4 cm, wider if a segment is long); within a bin a sort by the along-line start
    finds the pairs whose extents meet. Each candidate is then tested exactly. Work is
    O(N log N) plus the candidates (a few per segment in a building map).
    """
    n = seg.shape[0]
    if n < 2:
        return np.zeros((0, 2), np.int64)
    tol_a = math.radians(OVERLAP_ANGLE_DEG)
    tol_d = OVERLAP_DIST_M
    nb = int(math.pi / (2.2 * tol_a)) // 2 * 2  # even: bins centred on 0 and 90 degrees
    w = math.pi / nb
    x0, y0, x1, y1 = seg.T
    theta = np.mod(np.arctan2(y1 - y0, x1 - x0), math.pi)
    theta[theta >= math.pi] = 0.0
    lengths = np.hypot(x1 - x0, y1 - y0)

    # Grid B (every segment): bins [(k - 1/2) w, (k + 1/2) w), wrapped so that 0 and pi meet.
    tb = np.where(theta >= math.pi - w / 2, theta - math.pi, theta)
    kb = np.floor(tb / w + 0.5).astype(np.int64)
    # Grid A: bins [k w, (k + 1) w); only segments within the tolerance of a grid-B edge
    # need it (a pair closer than that to no edge already shares a grid-B bin).
    ka = np.floor(theta / w).astype(np.int64)
    in_a = np.abs(theta - (ka + 0.5) * w) <= tol_a * 1.01
    rows = np.concatenate([np.arange(n), np.flatnonzero(in_a)])
    group = np.concatenate([kb, nb + ka[in_a]])
    centre = np.concatenate([kb * w, (ka[in_a] + 0.5) * w])
    cs, sn = np.cos(centre), np.sin(centre)
    sx0, sy0, sx1, sy1 = x0[rows], y0[rows], x1[rows], y1[rows]
    u0, u1 = sx0 * cs + sy0 * sn, sx1 * cs + sy1 * sn
    v0, v1 = sy0 * cs - sx0 * sn, sy1 * cs - sx1 * sn
    umin, umax = np.minimum(u0, u1), np.maximum(u0, u1)

    # Perpendicular bins: a segment enters every bin its [vmin, vmax] +- tol_d touches.
    h = max(4 * tol_d, float(lengths.max()) * math.sin(w) / 16)
    vb0 = np.floor((np.minimum(v0, v1) - tol_d) / h).astype(np.int64)
    vb1 = np.floor((np.maximum(v0, v1) + tol_d) / h).astype(np.int64)
    cnt = vb1 - vb0 + 1
    e = np.repeat(np.arange(rows.size), cnt)
    vb = vb0[e] + (np.arange(e.size) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    key = group[e] * (int(vb.max() - vb.min()) + 1) + (vb - vb.min())
    ue0, ue1 = umin[e], umax[e]
    order = np.lexsort((ue0, key))
    key, ue0, ue1, src = key[order], ue0[order], ue1[order], rows[e[order]]

    # Sweep: within a bin (sorted by start), entry i meets every later entry starting
    # before its end. One searchsorted over "bin rank * span + start" finds them all.
    new = np.r_[True, key[1:] != key[:-1]]
    rank = np.cumsum(new) - 1
    lo = float(ue0.min())
    span = float(ue1.max()) - lo + 4 * tol_d + 1.0
    comp = rank * span + (ue0 - lo)
    end = np.searchsorted(comp, rank * span + (ue1 - lo) + tol_d, side="right")
    m = np.maximum(end - np.arange(key.size) - 1, 0)
    cm = np.cumsum(m)
    found = []
    lo_e = 0
    while lo_e < key.size:  # in chunks, so a pile of overlapping copies cannot exhaust memory
        hi_e = max(int(np.searchsorted(cm, cm[lo_e] - m[lo_e] + _CHUNK, side="right")), lo_e + 1)
        mc = m[lo_e:hi_e]
        i = np.repeat(np.arange(lo_e, hi_e), mc)
        j = i + 1 + (np.arange(i.size) - np.repeat(np.cumsum(mc) - mc, mc))
        a, b = src[i], src[j]  # never a == b: a segment enters a bin once
        ok = _overlapping(seg, a, b)
        found.append(np.minimum(a[ok], b[ok]) * n + np.maximum(a[ok], b[ok]))
        lo_e = hi_e
    pairs = _sorted_unique(np.concatenate(found)) if found else np.zeros(0, np.int64)
    return np.stack([pairs // n, pairs % n], axis=1)


def _overlapping(seg: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether segments ``a[k]`` and ``b[k]`` are on one line and overlap (the exact test).

    With ``a`` the longer of the two (so the test is symmetric), b's end points are at
    ``(t, w)`` along and across a. The pair overlaps if the directions differ by at most
    OVERLAP_ANGLE_DEG, b's part over ``[0, |a|]`` is longer than OVERLAP_MIN_M, and b is
    within OVERLAP_DIST_M of a's line at both ends of that part (so along all of it).
    """
    x0, y0, x1, y1 = seg.T
    length = np.hypot(x1 - x0, y1 - y0)
    swap = (length[b] > length[a]) | ((length[b] == length[a]) & (b < a))
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    ax, ay = x0[a], y0[a]
    la, lb = length[a], length[b]
    ux, uy = (x1[a] - ax) / la, (y1[a] - ay) / la
    bx0, by0, bx1, by1 = x0[b] - ax, y0[b] - ay, x1[b] - ax, y1[b] - ay
    parallel = np.abs((bx1 - bx0) * uy - (by1 - by0) * ux) <= math.sin(math.radians(OVERLAP_ANGLE_DEG)) * lb
    t0, t1 = bx0 * ux + by0 * uy, bx1 * ux + by1 * uy
    w0, w1 = by0 * ux - bx0 * uy, by1 * ux - bx1 * uy
    flip = t1 < t0
    t0, t1 = np.where(flip, t1, t0), np.where(flip, t0, t1)
    w0, w1 = np.where(flip, w1, w0), np.where(flip, w0, w1)
    s0, s1 = np.maximum(t0, 0.0), np.minimum(t1, la)
    overlap = (s1 - s0) > OVERLAP_MIN_M
    dt = np.where(t1 > t0, t1 - t0, 1.0)
    w_lo = w0 + (s0 - t0) / dt * (w1 - w0)
    w_hi = w0 + (s1 - t0) / dt * (w1 - w0)
    near = (np.abs(w_lo) <= OVERLAP_DIST_M) & (np.abs(w_hi) <= OVERLAP_DIST_M)
    return parallel & overlap & near


def _extent_finding(
    seg: np.ndarray, kept: np.ndarray, source: str, labels: Any, unit: str
) -> Finding | None:
    xs, ys = seg[:, 0::2], seg[:, 1::2]
    xmin, xmax, ymin, ymax = xs.min(), xs.max(), ys.min(), ys.max()
    width, height = float(xmax - xmin), float(ymax - ymin)
    big = max(width, height)
    if MIN_EXTENT_M <= big <= WARN_EXTENT_M:
        return None
    c, cs = ("x", xs) if width >= height else ("y", ys)
    r_lo = int(kept[np.argmin(cs) // 2])
    r_hi = int(kept[np.argmax(cs) // 2])
    lo, hi = float(cs.min()), float(cs.max())
    one = unit.removesuffix("(s)")
    where = f"{c} from {_metres(lo)} at {one} {labels[r_lo]} to {_metres(hi)} at {one} {labels[r_hi]}"
    size = f"{_metres(width)} x {_metres(height)} m"
    rows = sorted({r_lo, r_hi})
    if big > MAX_EXTENT_M:
        if big * 1e-3 <= MAX_EXTENT_M:
            what = "looks like millimetres; scale by 0.001 (depthnav map convert IN OUT --scale 0.001)"
        else:
            what = "not a building in metres (a stray coordinate?)"
        return Finding(
            "extent", "error", f"{source}: map extent {size} is over {MAX_EXTENT_M:.0f} m: {what} ({where})", rows
        )
    if big < MIN_EXTENT_M:
        return Finding(
            "extent",
            "error",
            f"{source}: map extent {size} is under {MIN_EXTENT_M} m: not a building in metres "
            f"(kilometres? scale by 1000) or a broken file ({where})",
            rows,
        )
    return Finding(
        "extent",
        "warning",
        f"{source}: map extent {size} is over {WARN_EXTENT_M:.0f} m, large for one building: "
        f"check the units (centimetres need scale 0.01, millimetres 0.001) ({where})",
        rows,
    )


def clean_segments(
    segments: Any,
    source: str = "<string>",
    labels: Any = None,
    unit: str = "segment(s)",
    *,
    checks: bool = True,
    applied: bool = True,
) -> Cleaned:
    """Check parsed wall segments; return the rows to keep and the findings.

    ``segments`` is (N, 4) ``x1, y1, x2, y2`` in metres. ``labels[i]`` names row ``i`` in
    messages (a line number, ``"[i] (line L)"``; default ``"[i]"``) and ``unit`` what the
    labels count (``"line(s)"``, ``"element(s)"``). Only the first :data:`MAX_LISTED`
    labels of a finding are asked for. ``checks=False`` runs only what a
    :class:`~autonomy.maps.vectormap.VectorMap` needs (finite; zero-length means exactly zero,
    not under :data:`ROUND_M`).
    ``applied=False`` words the messages for a map that is only being checked ("would
    drop"). Nothing is raised for the map's content: errors are findings.
    """
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    labels = _IndexLabels() if labels is None else labels
    drop = "dropped" if applied else "would drop"
    n = seg.shape[0]
    findings: list[Finding] = []
    kept = np.arange(n, dtype=np.int64)

    def where(rows: np.ndarray) -> str:
        return _listing(rows, lambda r: str(labels[int(r)]))

    bad = ~np.isfinite(seg).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)
        first = labels[int(rows[0])]
        findings.append(
            Finding(
                "non_finite",
                "error",
                f"{source}: {rows.size} segment(s) with a NaN or infinite coordinate at {unit} {where(rows)}",
                rows,
                line=first if isinstance(first, int) else None,
            )
        )
        return Cleaned(seg[:0], kept[:0], tuple(findings))

    q = _rounded(seg) if checks else seg
    zero = (q[:, 0] == q[:, 2]) & (q[:, 1] == q[:, 3])
    if zero.any():
        rows = np.flatnonzero(zero)
        findings.append(
            Finding(
                "zero_length",
                "warning",
                f"{source}: {drop} {rows.size} zero-length segment(s) at {unit} {where(rows)}",
                rows,
            )
        )
        kept = kept[~zero]
        if kept.size == 0:
            findings.append(
                Finding("no_segments", "error", f"{source}: no wall segments left after dropping zero-length ones")
            )
            return Cleaned(seg[:0], kept, tuple(findings))

    if checks:
        dup, first = _duplicates(_canonical(q[kept]))
        if dup.size:
            d_rows, f_rows = kept[dup], kept[first]
            findings.append(
                Finding(
                    "duplicate",
                    "warning",
                    f"{source}: {drop} {d_rows.size} duplicate segment(s) at {unit} "
                    + _listing(np.stack([d_rows, f_rows], 1), lambda p: f"{labels[int(p[0])]} = {labels[int(p[1])]}")
                    + " (the end points of the earlier one, in either direction; kept the earlier)",
                    d_rows,
                )
            )
            keep = np.ones(kept.size, bool)
            keep[dup] = False
            kept = kept[keep]

        ext = _extent_finding(seg[kept], kept, source, labels, unit)
        if ext is not None:
            findings.append(ext)
        if ext is None or ext.severity != "error":
            pairs = kept[_overlap_pairs(seg[kept])]  # sorted, as kept is increasing
            if pairs.size:
                involved = np.zeros(n, bool)
                involved[pairs.ravel()] = True
                listed = _listing(pairs, lambda p: f"{labels[int(p[0])]} & {labels[int(p[1])]}")
                findings.append(
                    Finding(
                        "overlap",
                        "warning",
                        f"{source}: {pairs.shape[0]} pair(s) of overlapping collinear segments at {unit} "
                        f"{listed} (kept as they are; merge each pair into one wall)",
                        np.flatnonzero(involved),
                        pairs,
                    )
                )
    return Cleaned(seg[kept], kept, tuple(findings))


def log_findings(findings: Iterable[Finding], logger: logging.Logger | None = None) -> None:
    """Log each finding as one warning line on the ``"depthnav.map"`` logger."""
    log = logger if logger is not None else logging.getLogger(LOGGER_NAME)
    for f in findings:
        log.warning("%s", f.message)
