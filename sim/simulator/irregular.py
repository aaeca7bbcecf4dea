"""Hand-drawn irregularity for generated floors: skewed walls, jittered corners, door
recesses, jogs, broken and doubled lines.

Real floor plans are drawn by people: neighbouring walls are rarely exactly parallel or
square, corners sit a centimetre or two off, doors sit in shallow recesses, walls jog,
break into short pieces and are sometimes drawn twice a few centimetres apart. A
localizer tested only on exactly square floors can fail on such maps, so
:func:`irregular_walls` turns the generator's axis-aligned walls into walls like these.

The edits keep the floor valid: corners and T-junctions stay closed (a corner's
displacement is shared by every wall that ends there, and a wall that ends on another
wall's side is moved onto that wall's new line), and any edit that would bring a wall
closer than ``min_clearance_m`` to a navigation-graph edge is left out (a skewed wall is
then kept straight). Every draw comes from the generator's ``numpy.random.Generator``,
after the floor's layout has been drawn, so a seed gives the same layout with or without
irregularity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import WallIndex

__all__ = ["Irregularity", "Piece", "Door", "irregular_walls"]

Piece = tuple[bool, float, float, float]
"""An axis-aligned wall ``(horizontal, c, a, b)``: on the line y = c (x = c when vertical)
from a to b along it, a < b."""

Door = tuple[bool, float, float, float, float]
"""A doorway ``(horizontal, c, lo, hi, inward)``: a gap lo..hi in the wall on line c and
the sign of the direction into its room."""

_RUN_GAP_M = 1.5
"""Pieces on one line with gaps up to this (doorways, jogs) are one wall and skew together."""
_EPS_M = 0.05
"""A recess or jog needs this much room from every other wall."""
_MIN_PIECE_M = 0.1
"""Recesses, jogs and breaks leave no piece shorter than this."""


def _q(x: float) -> float:
    """Quantise a coordinate to the millimetre (and turn -0.0 into 0.0)."""
    return round(float(x), 3) + 0.0


@dataclass(frozen=True)
class Irregularity:
    """How far generated walls depart from an exactly square drawing (metres, degrees).

    The defaults resemble a hand-drawn CoBot map; :meth:`none` (or all zeros) keeps the
    generator's exact axis-aligned geometry."""

    max_wall_skew_deg: float = 1.5
    """Each wall turns by up to this about its middle (less when long, see below)."""
    max_skew_offset_m: float = 0.05
    """... but its ends move at most this far, so a 20 m wall turns by at most 0.3 degrees."""
    corner_jitter_m: float = 0.015
    """Each wall end (shared by the walls meeting there) moves up to this along each axis."""
    recess_probability: float = 0.3
    """Chance that a doorway sits in a recess into its room."""
    recess_depth_m: tuple[float, float] = (0.15, 0.25)
    """Depth of a door recess."""
    recess_margin_m: tuple[float, float] = (0.05, 0.2)
    """How far a recess reaches beyond each side of its doorway."""
    jog_probability: float = 0.1
    """Chance that a wall piece at least 2 m long gets a jog (a stretch set off to one side)."""
    jog_width_m: tuple[float, float] = (0.3, 1.2)
    """Length of a jog along its wall."""
    jog_depth_m: tuple[float, float] = (0.1, 0.3)
    """How far a jog is set off from its wall."""
    double_line_probability: float = 0.05
    """Chance that a wall segment at least 0.5 m long is drawn twice, side by side."""
    double_line_gap_m: tuple[float, float] = (0.03, 0.1)
    """Distance between a wall and its second drawing."""
    split_probability: float = 0.15
    """Chance that a wall piece at least 0.6 m long is broken into two or three segments
    (each break point is off the line by a few millimetres)."""

    def __post_init__(self) -> None:
        def bad(name: str, what: str) -> InputError:
            return InputError(f"Irregularity.{name}: expected {what}, got {getattr(self, name)!r}")

        for f in fields(self):
            v = getattr(self, f.name)
            if f.name.endswith("_probability"):
                if not (isinstance(v, int | float) and 0.0 <= v <= 1.0):
                    raise bad(f.name, "a probability in [0, 1]")
            elif isinstance(v, tuple):
                if not (len(v) == 2 and all(math.isfinite(x) for x in v) and 0.0 < v[0] <= v[1]):
                    raise bad(f.name, "a range (lo, hi) with 0 < lo <= hi")
            elif not (isinstance(v, int | float) and math.isfinite(v) and v >= 0.0):
                raise bad(f.name, "a number >= 0")
        if self.max_wall_skew_deg > 10.0:
            raise bad("max_wall_skew_deg", "at most 10 degrees")
        if self.corner_jitter_m > 0.1 or self.max_skew_offset_m > 0.2:
            raise InputError(
                "Irregularity: corner_jitter_m at most 0.1 m and max_skew_offset_m at most 0.2 m "
                f"(walls move by centimetres), got {self.corner_jitter_m!r} and {self.max_skew_offset_m!r}"
            )
        if self.double_line_gap_m[0] < 0.02:
            raise bad("double_line_gap_m", "a range starting at 0.02 m or more")

    @classmethod
    def none(cls) -> Irregularity:
        """The generator's exact, axis-aligned walls."""
        return cls(
            max_wall_skew_deg=0.0, max_skew_offset_m=0.0, corner_jitter_m=0.0, recess_probability=0.0,
            jog_probability=0.0, double_line_probability=0.0, split_probability=0.0,
        )

    @property
    def active(self) -> bool:
        """Whether anything moves (False: the generator's exact walls, drawing nothing)."""
        skew = self.max_wall_skew_deg > 0 and self.max_skew_offset_m > 0
        return bool(
            skew or self.corner_jitter_m > 0 or self.recess_probability > 0 or self.jog_probability > 0
            or self.double_line_probability > 0 or self.split_probability > 0
        )

    @property
    def max_move_m(self) -> float:
        """The most a wall end moves along either axis when skewed and jittered."""
        return self.max_skew_offset_m + self.corner_jitter_m


# --------------------------------------------------------------------------- the edits


class _Plan:
    """The axis-aligned pieces being edited, each with the wall (run) it skews with."""

    def __init__(self, pieces: list[Piece], extra: np.ndarray, edges: WallIndex, min_clear: float) -> None:
        self.pieces: list[Piece | None] = list(pieces)
        self.run: list[int] = []
        self.extra = extra
        self.edges, self.min_clear = edges, min_clear
        cap = len(pieces) + 64
        self.bbox = np.full((cap, 4), np.nan)
        for i, p in enumerate(pieces):
            self.bbox[i] = self._box(p)
        self.n = len(pieces)
        self.at_end: dict[tuple[bool, float, float, bool], int] = {}
        for i, p in enumerate(pieces):
            self._index(i, p, True)
        ex = extra.reshape(-1, 4)
        self.extra_bbox = np.column_stack(
            [np.minimum(ex[:, 0], ex[:, 2]), np.minimum(ex[:, 1], ex[:, 3]),
             np.maximum(ex[:, 0], ex[:, 2]), np.maximum(ex[:, 1], ex[:, 3])]
        )
        self._assign_runs()

    @staticmethod
    def _box(p: Piece) -> tuple[float, float, float, float]:
        h, c, a, b = p
        return (a, c, b, c) if h else (c, a, c, b)

    def _assign_runs(self) -> None:
        """Pieces on one line with gaps of at most ``_RUN_GAP_M`` form one run."""
        by_line: dict[tuple[bool, float], list[int]] = {}
        for i, p in enumerate(self.pieces):
            assert p is not None
            by_line.setdefault((p[0], p[1]), []).append(i)
        self.run = [-1] * len(self.pieces)
        n_runs = 0
        for key in sorted(by_line):
            idx = sorted(by_line[key], key=lambda i: self.pieces[i][2])  # type: ignore[index]
            end = -math.inf
            for i in idx:
                p = self.pieces[i]
                assert p is not None
                if p[2] - end > _RUN_GAP_M:
                    n_runs += 1
                self.run[i] = n_runs - 1
                end = max(end, p[3])

    def _index(self, i: int, p: Piece, live: bool) -> None:
        for upper, at in ((False, p[2]), (True, p[3])):
            key = (p[0], p[1], at, upper)
            if live:
                self.at_end[key] = i
            elif self.at_end.get(key) == i:
                del self.at_end[key]

    def add(self, p: Piece, run: int) -> None:
        if self.n == self.bbox.shape[0]:
            self.bbox = np.vstack([self.bbox, np.full((self.n, 4), np.nan)])
        self.pieces.append(p)
        self.run.append(run)
        self.bbox[self.n] = self._box(p)
        self._index(self.n, p, True)
        self.n += 1

    def remove(self, i: int) -> None:
        p = self.pieces[i]
        assert p is not None
        self._index(i, p, False)
        self.pieces[i] = None
        self.bbox[i] = np.nan

    def free(self, box: tuple[float, float, float, float], skip: tuple[int, ...]) -> bool:
        """Whether no wall but the pieces ``skip`` comes within ``_EPS_M`` of ``box``."""
        x0, y0, x1, y1 = box[0] - _EPS_M, box[1] - _EPS_M, box[2] + _EPS_M, box[3] + _EPS_M
        b = self.bbox[: self.n]
        hit = (b[:, 0] <= x1) & (b[:, 2] >= x0) & (b[:, 1] <= y1) & (b[:, 3] >= y0)
        hit[list(skip)] = False
        if hit.any():
            return False
        e = self.extra_bbox
        return not ((e[:, 0] <= x1) & (e[:, 2] >= x0) & (e[:, 1] <= y1) & (e[:, 3] >= y0)).any()

    def clear_of_graph(self, new: list[Piece], margin: float) -> bool:
        """Whether every new piece keeps ``min_clear + margin`` from every nav edge."""
        segs = np.array([self._box(p) for p in new], dtype=np.float64)
        need = self.min_clear + margin
        return bool((self.edges.clearances(segs, need + 0.01) >= need).all())

    def find_end(self, h: bool, c: float, at: float, upper: bool) -> int:
        """The live piece on line (h, c) whose upper (or lower) end is ``at``; -1 if none."""
        return self.at_end.get((h, c, at, upper), -1)


def _recess(plan: _Plan, door: Door, depth: float, margin: float, slack: float) -> bool:
    """Set a doorway back ``depth`` into its room, the recess ``margin`` wider than the door
    on each side; False (nothing changed) where it does not fit."""
    h, c, lo, hi, inward = door
    left, right = plan.find_end(h, c, lo, True), plan.find_end(h, c, hi, False)
    if left < 0 or right < 0:
        return False
    pl, pr = plan.pieces[left], plan.pieces[right]
    assert pl is not None and pr is not None
    a, b = _q(lo - margin), _q(hi + margin)
    if a - pl[2] < _MIN_PIECE_M or pr[3] - b < _MIN_PIECE_M:
        return False
    c2 = _q(c + inward * depth)
    box = (a, min(c, c2), b, max(c, c2)) if h else (min(c, c2), a, max(c, c2), b)
    if not plan.free(box, (left, right)):
        return False
    new_h = [(h, c, pl[2], a), (h, c, b, pr[3]), (h, c2, a, lo), (h, c2, hi, b)]
    new_v = [(not h, a, min(c, c2), max(c, c2)), (not h, b, min(c, c2), max(c, c2))]
    if not plan.clear_of_graph(new_v + new_h[2:], slack):
        return False
    run_l, run_r = plan.run[left], plan.run[right]
    plan.remove(left)
    plan.remove(right)
    for p, r in zip(new_h, (run_l, run_r, run_l, run_r), strict=True):
        plan.add(p, r)
    for p in new_v:
        plan.add(p, -1)
    return True


def _jog(plan: _Plan, i: int, s: float, w: float, depth: float, slack: float) -> bool:
    """Set the stretch s..s+w of piece ``i`` off its line by ``depth`` (signed); False
    (nothing changed) where it does not fit."""
    p = plan.pieces[i]
    assert p is not None
    h, c, a, b = p
    s, e, c2 = _q(s), _q(s + w), _q(c + depth)
    if s - a < _MIN_PIECE_M or b - e < _MIN_PIECE_M:
        return False
    box = (s, min(c, c2), e, max(c, c2)) if h else (min(c, c2), s, max(c, c2), e)
    if not plan.free(box, (i,)):
        return False
    lo, hi = min(c, c2), max(c, c2)
    new = [(h, c2, s, e), (not h, s, lo, hi), (not h, e, lo, hi)]
    if not plan.clear_of_graph(new, slack):
        return False
    run = plan.run[i]
    plan.remove(i)
    plan.add((h, c, a, s), run)
    plan.add((h, c, e, b), run)
    plan.add(new[0], run)
    plan.add(new[1], -1)
    plan.add(new[2], -1)
    return True


# --------------------------------------------------------------------------- skew and jitter


class _Topology:
    """Where the pieces' ends meet: which pieces end at each corner and which piece's side
    each free end rests on (a T-junction)."""

    def __init__(self, pieces: list[Piece]) -> None:
        keys: set[tuple[float, float]] = set()
        for h, c, a, b in pieces:
            keys.update([(a, c), (b, c)] if h else [(c, a), (c, b)])
        self.keys = sorted(keys)
        index = {k: n for n, k in enumerate(self.keys)}
        self.xy = np.array(self.keys, dtype=np.float64).reshape(-1, 2)
        nv = len(self.keys)
        self.ends = np.empty((len(pieces), 2), dtype=np.int64)
        self.h_end = [-1] * nv
        self.v_end = [-1] * nv
        lines: dict[tuple[bool, float], list[int]] = {}
        for i, (h, c, a, b) in enumerate(pieces):
            k0, k1 = ((a, c), (b, c)) if h else ((c, a), (c, b))
            self.ends[i] = index[k0], index[k1]
            for k in (k0, k1):
                if h:
                    self.h_end[index[k]] = i
                else:
                    self.v_end[index[k]] = i
            lines.setdefault((h, c), []).append(i)
        # T-junctions: a corner where no piece of one direction ends but one passes by
        self.h_host = [-1] * nv
        self.v_host = [-1] * nv
        for n, (x, y) in enumerate(self.keys):
            if self.h_end[n] < 0:
                self.h_host[n] = next((i for i in lines.get((True, y), []) if pieces[i][2] < x < pieces[i][3]), -1)
            if self.v_end[n] < 0:
                self.v_host[n] = next((i for i in lines.get((False, x), []) if pieces[i][2] < y < pieces[i][3]), -1)


def _displacements(
    pieces: list[Piece], topo: _Topology, tan_run: np.ndarray, centre_run: np.ndarray,
    run: list[int], jitter: np.ndarray, frozen: set[int],
) -> np.ndarray:
    """(V, 2) displacement of every corner: a wall's end moves across the wall with the
    wall's turn plus the corner's jitter, and along it with the jitter (or the turn of the
    wall ending across); an end resting on another wall's side stays on that wall. Corners
    of ``frozen`` pieces (and the walls they rest on) stay where they were."""
    fv: set[int] = set()
    todo = list(frozen)
    seen_p = set(frozen)
    while todo:
        i = todo.pop()
        for v in topo.ends[i].tolist():
            if v in fv:
                continue
            fv.add(v)
            for host in (topo.h_host[v], topo.v_host[v]):
                if host >= 0 and host not in seen_p:
                    seen_p.add(host)
                    todo.append(host)
    xy = topo.xy
    d = np.zeros_like(xy)
    deferred: list[tuple[int, int, int]] = []  # (corner, axis across the host, host)
    for v in range(len(topo.keys)):
        if v in fv:
            continue
        for axis, end, host in ((1, topo.h_end[v], topo.h_host[v]), (0, topo.v_end[v], topo.v_host[v])):
            if end >= 0:
                r = run[end]
                along = xy[v, 0] if axis == 1 else xy[v, 1]
                d[v, axis] = tan_run[r] * (along - centre_run[r]) + jitter[v, axis]
            elif host >= 0:
                deferred.append((v, axis, host))
            else:
                d[v, axis] = jitter[v, axis]
    for _ in range(3):  # a host's own ends may rest on other walls: settle in a few sweeps
        for v, axis, host in deferred:
            v0, v1 = topo.ends[host]
            p0, p1 = xy[v0] + d[v0], xy[v1] + d[v1]
            ax = 1 - axis  # along the host
            t = (xy[v, ax] + d[v, ax] - p0[ax]) / (p1[ax] - p0[ax])
            d[v, axis] = p0[axis] + t * (p1[axis] - p0[axis]) - xy[v, axis]
    return d


def _perturb(
    pieces: list[Piece], run: list[int], bound: dict[tuple[float, float], float], irr: Irregularity,
    rng: np.random.Generator, edges: WallIndex, min_clear: float,
) -> np.ndarray:
    """(P, 4) skewed and jittered pieces (mm-quantised); a piece that would come closer
    than ``min_clear`` to a nav edge is kept where it was, with the corners it shares.
    A break point in a wall (a key of ``bound``) moves across the wall at most its bound."""
    topo = _Topology(pieces)
    n_runs = max(run) + 1 if run else 0
    lo = np.full(n_runs, np.inf)
    hi = np.full(n_runs, -np.inf)
    for (_, _, a, b), r in zip(pieces, run, strict=True):
        lo[r], hi[r] = min(lo[r], a), max(hi[r], b)
    half = np.maximum((hi - lo) / 2, 1e-9)
    limit = np.minimum(math.tan(math.radians(irr.max_wall_skew_deg)), irr.max_skew_offset_m / half)
    tan_run = rng.uniform(-1.0, 1.0, n_runs) * limit
    centre = (lo + hi) / 2
    jitter = rng.uniform(-irr.corner_jitter_m, irr.corner_jitter_m, (len(topo.keys), 2))
    if irr.corner_jitter_m > 0:
        for n, key in enumerate(topo.keys):
            if key in bound and topo.v_end[n] < 0:  # across a horizontal wall: along y
                jitter[n, 1] *= bound[key] / irr.corner_jitter_m
            elif key in bound and topo.h_end[n] < 0:
                jitter[n, 0] *= bound[key] / irr.corner_jitter_m
    old = np.concatenate([topo.xy[topo.ends[:, 0]], topo.xy[topo.ends[:, 1]]], axis=1)
    old_d = old[:, 2:] - old[:, :2]
    frozen: set[int] = set()
    for _ in range(20):
        d = _displacements(pieces, topo, tan_run, centre, run, jitter, frozen)
        xy = np.round(topo.xy + d, 3) + 0.0
        segs = np.concatenate([xy[topo.ends[:, 0]], xy[topo.ends[:, 1]]], axis=1)
        clear = edges.clearances(segs, min_clear + 0.01)
        # a short piece between corners moved apart must not shrink to nothing or flip
        kept = ((segs[:, 2:] - segs[:, :2]) * old_d).sum(axis=1) >= 0.5 * (old_d * old_d).sum(axis=1)
        bad = set(np.nonzero((clear < min_clear) | ~kept)[0].tolist()) - frozen
        if not bad:
            return segs
        frozen |= bad
    d = _displacements(pieces, topo, tan_run, centre, run, jitter, set(range(len(pieces))))
    xy = topo.xy + d
    return np.concatenate([xy[topo.ends[:, 0]], xy[topo.ends[:, 1]]], axis=1)


# --------------------------------------------------------------------------- breaks and doubles


def _breaks(
    pieces: list[Piece], runs: list[int], irr: Irregularity, rng: np.random.Generator,
    max_segment_m: float | None,
) -> tuple[list[Piece], list[int], dict[tuple[float, float], float]]:
    """The pieces broken where drawn (``split_probability``: one or two breaks) and into
    parts of at most ``max_segment_m``, with how far each break point may move across its
    wall (little, so the parts stay within a degree or so of each other)."""
    out: list[Piece] = []
    out_runs: list[int] = []
    bound: dict[tuple[float, float], float] = {}
    tan_skew = math.tan(math.radians(irr.max_wall_skew_deg))
    for (h, c, a, b), r in zip(pieces, runs, strict=True):
        ts = [a]
        if rng.random() < irr.split_probability and b - a >= 0.6:
            for t in np.sort(rng.uniform(a + _MIN_PIECE_M, b - _MIN_PIECE_M, int(rng.integers(1, 3)))).tolist():
                if _q(t) - ts[-1] >= _MIN_PIECE_M and b - _q(t) >= _MIN_PIECE_M:
                    ts.append(_q(t))
        ts.append(b)
        if max_segment_m is not None:
            fine = [a]
            for lo, hi in zip(ts[:-1], ts[1:], strict=True):
                n = math.ceil((hi - lo) / max_segment_m - 1e-9)
                fine.extend([_q(lo + (hi - lo) * k / n) for k in range(1, n)] + [hi])
            ts = fine
        for k in range(1, len(ts) - 1):
            key = (ts[k], c) if h else (c, ts[k])
            bound[key] = min(irr.corner_jitter_m, 0.5 * tan_skew * min(ts[k] - ts[k - 1], ts[k + 1] - ts[k]))
        out.extend((h, c, lo, hi) for lo, hi in zip(ts[:-1], ts[1:], strict=True))
        out_runs.extend([r] * (len(ts) - 1))
    return out, out_runs, bound


def _doubles(
    segs: np.ndarray, irr: Irregularity, rng: np.random.Generator, edges: WallIndex, min_clear: float
) -> np.ndarray:
    """Second drawings of some segments: part of the segment, a few centimetres to one side
    (the other side where that would come too near a nav edge), its ends a little askew."""
    length = np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
    out = []
    for i in range(segs.shape[0]):
        if rng.random() >= irr.double_line_probability or length[i] < 0.5:
            continue
        u0, u1 = rng.uniform(0.0, 0.3), rng.uniform(0.7, 1.0)
        gap = rng.uniform(*irr.double_line_gap_m)
        skew = rng.uniform(-1.0, 1.0, 2) * min(irr.corner_jitter_m, gap / 3)
        side = 1.0 if rng.random() < 0.5 else -1.0
        p0, p1 = segs[i, :2], segs[i, 2:]
        u = (p1 - p0) / length[i]
        n = np.array([-u[1], u[0]])
        for sgn in (side, -side):
            a = p0 + (p1 - p0) * u0 + n * (sgn * gap + skew[0])
            b = p0 + (p1 - p0) * u1 + n * (sgn * gap + skew[1])
            cand = np.round(np.concatenate([a, b]), 3)[None] + 0.0
            if edges.clearances(cand, min_clear + 0.01)[0] >= min_clear:
                out.append(cand)
                break
    return np.concatenate([segs, *out]) if out else segs


# --------------------------------------------------------------------------- entry point


def irregular_walls(
    pieces: list[Piece],
    extra: np.ndarray,
    doors: list[Door],
    nav_edges: np.ndarray,
    irr: Irregularity,
    rng: np.random.Generator,
    min_clearance_m: float,
    max_segment_m: float | None = None,
) -> np.ndarray:
    """(N, 4) wall segments: the axis-aligned ``pieces`` (in order) with door recesses and
    jogs, broken (also into pieces of at most ``max_segment_m``), skewed and jittered,
    some drawn twice, then the free-standing ``extra`` segments as they are.

    No segment comes closer than ``min_clearance_m`` to a ``nav_edges`` segment unless a
    piece already did."""
    edges = WallIndex(nav_edges)
    plan = _Plan(pieces, np.asarray(extra, dtype=np.float64).reshape(-1, 4), edges, min_clearance_m)
    slack = irr.max_move_m + irr.corner_jitter_m  # edits made before the skew keep room for it
    for door in doors:
        if rng.random() < irr.recess_probability:
            depth, margin = rng.uniform(*irr.recess_depth_m), rng.uniform(*irr.recess_margin_m)
            _recess(plan, door, depth, margin, slack)
    for i in range(len(pieces)):
        p = plan.pieces[i]
        if rng.random() >= irr.jog_probability or p is None or p[3] - p[2] < 2.0:
            continue
        w = rng.uniform(*irr.jog_width_m)
        s = rng.uniform(p[2] + 0.3, max(p[2] + 0.3, p[3] - 0.3 - w))
        depth = rng.uniform(*irr.jog_depth_m) * (1.0 if rng.random() < 0.5 else -1.0)
        _jog(plan, i, s, w, depth, slack)
    live = [i for i, p in enumerate(plan.pieces) if p is not None]
    kept = [plan.pieces[i] for i in live]
    runs = [plan.run[i] for i in live]
    n_runs = max(runs) + 1 if runs else 0
    for k, r in enumerate(runs):  # the pieces the edits added across their walls skew alone
        if r < 0:
            runs[k] = n_runs
            n_runs += 1
    kept, runs, bound = _breaks(kept, runs, irr, rng, max_segment_m)  # type: ignore[arg-type]
    segs = _perturb(kept, runs, bound, irr, rng, edges, min_clearance_m)
    segs = _doubles(segs, irr, rng, edges, min_clearance_m)
    return np.concatenate([segs, plan.extra]) if plan.extra.size else segs
