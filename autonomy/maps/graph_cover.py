"""Covering wide free space with extra nodes (step 5 of :mod:`autonomy.maps.graph_builder`).

Free space farther than ``cover_radius_m`` from every edge (wide halls, open sites) gets
a square lattice of nodes ``cover_spacing_m`` apart, turned to the walls' main direction,
joined to its lattice neighbours and to the graph by clear straight edges; what the
lattice misses (room corners) gets single nodes, farthest first.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from autonomy.maps.freespace import FreeSpace, grid_distance, rasterise
from autonomy.maps.graph_config import GraphBuildConfig
from autonomy.maps.graph_edges import _ROUNDING_M, _Builder, _segments, graph_components

__all__ = ["distance_to_segments", "distance_to_cells", "dominant_angle"]


def distance_to_segments(fs: FreeSpace, segments: np.ndarray) -> np.ndarray:
    """(ny, nx) grid distance in metres from each cell centre to the nearest of ``segments``
    (rasterised as the walls are; error below one cell)."""
    seg = np.ascontiguousarray(np.asarray(segments, dtype=np.float64).reshape(-1, 4))
    ny, nx = fs.shape
    if seg.shape[0] == 0:
        return np.full((ny, nx), np.inf, dtype=np.float32)
    return grid_distance(rasterise(seg, fs.origin[0], fs.origin[1], fs.cell_m, ny, nx), fs.cell_m)


def distance_to_cells(fs: FreeSpace, cells: np.ndarray) -> np.ndarray:
    """(ny, nx) grid distance in metres to the nearest True cell of ``cells``."""
    return grid_distance(cells, fs.cell_m)


@numba.njit(cache=True)
def _spread(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int], radius: int) -> np.ndarray:  # pragma: no cover - numba
    """Greedy farthest-first selection: take each candidate cell (given best first) unless
    an already taken one is within ``radius`` cells."""
    blocked = np.zeros(shape, dtype=np.bool_)
    take = np.zeros(rows.size, dtype=np.bool_)
    r2 = radius * radius
    for k in range(rows.size):
        y, x = rows[k], cols[k]
        if blocked[y, x]:
            continue
        take[k] = True
        for dy in range(-radius, radius + 1):
            for dx in range(-radius, radius + 1):
                yy, xx = y + dy, x + dx
                if dy * dy + dx * dx <= r2 and 0 <= yy < shape[0] and 0 <= xx < shape[1]:
                    blocked[yy, xx] = True
    return take


def _graph_distance(b: _Builder, fs: FreeSpace) -> np.ndarray:
    """(ny, nx) grid distance to the nearest edge or node of the graph under construction."""
    segs = _segments(b)
    if len(b.xy):
        nodes = np.asarray(b.xy)
        segs = np.concatenate([segs, np.concatenate([nodes, nodes], axis=1)])
    return distance_to_segments(fs, segs)


def _cover(b: _Builder, fs: FreeSpace, graph_ok: np.ndarray, cfg: GraphBuildConfig, rounds: int = 3) -> None:
    """Add nodes where free space is farther than ``cover_radius_m`` from the graph: in each
    uncovered patch the farthest cells first, ``cover_spacing_m`` apart, each joined to
    the graph by clear straight edges."""
    target = fs.region >= 0
    for _ in range(rounds):
        far = _graph_distance(b, fs)
        uncovered = (far > cfg.cover_radius_m) & target
        if not uncovered.any():
            return
        # candidates: cells with the graph clearance in or next to an uncovered patch
        near = distance_to_cells(fs, uncovered) <= 0.5 * cfg.cover_spacing_m
        # prefer places away from the walls (a node in a room's corner would hug two walls,
        # and its edges would look like doorways): near a patch a roomy place can serve,
        # only roomy places are candidates
        roomy = near & graph_ok & (fs.clearance() >= max(cfg.clearance_m, cfg.fill_clearance_m))
        cand = roomy
        if roomy.any():
            served = distance_to_cells(fs, roomy) <= cfg.cover_radius_m
            rest = uncovered & ~served
            if rest.any():
                cand = roomy | (near & graph_ok & (distance_to_cells(fs, rest) <= 0.5 * cfg.cover_spacing_m))
        else:
            cand = near & graph_ok
        rows, cols = np.nonzero(cand)
        if rows.size == 0:
            return
        order = np.argsort(-far[rows, cols], kind="stable")
        rows, cols = rows[order], cols[order]
        take = _spread(rows, cols, fs.shape, max(1, int(round(cfg.cover_spacing_m / fs.cell_m))))
        added = [b.node(p) for p in fs.centres(rows[take], cols[take])]
        _connect(b, added, cfg)


def dominant_angle(segments: np.ndarray) -> float:
    """The walls' main direction modulo 90 degrees, in [0, pi/2): the length-weighted mode
    of the segment directions (1 degree bins), refined by the mean of those within 2 degrees."""
    d = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    d = d[:, 2:] - d[:, :2]
    w = np.hypot(d[:, 0], d[:, 1])
    if not (w > 0).any():
        return 0.0
    q = np.mod(4.0 * np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)  # directions mod 90 deg, times 4
    hist = np.bincount(np.minimum((q / (2 * np.pi) * 360).astype(np.int64), 359), weights=w, minlength=360)
    # smooth over neighbouring bins (circularly) before taking the mode
    sm = hist + np.roll(hist, 1) + np.roll(hist, -1)
    mode = (np.argmax(sm) + 0.5) / 360 * 2 * np.pi
    near = np.abs(np.angle(np.exp(1j * (q - mode)))) <= np.radians(8.0)
    z = np.sum(w[near] * np.exp(1j * q[near]))
    return float(np.mod(np.angle(z) if abs(z) > 0 else mode, 2 * np.pi) / 4.0)


def _lattice(b: _Builder, fs: FreeSpace, graph_ok: np.ndarray, cfg: GraphBuildConfig, theta: float) -> None:
    """A square lattice of nodes (``cover_spacing_m``, turned by ``theta``) where free space is
    farther than ``cover_radius_m`` from the graph, each joined to its lattice neighbours and,
    when one is within a lattice step, to the nearest old node it sees; a lattice piece that
    reaches no old node is joined by its shortest clear link (or left out when its region
    has other nodes, so that a region stays one component)."""
    far = _graph_distance(b, fs)
    uncovered = (far > cfg.cover_radius_m) & (fs.region >= 0)
    if not uncovered.any():
        return
    s = cfg.cover_spacing_m
    # lattice nodes only where the walls are at least fill_clearance_m away (a node by a
    # wall would make its edges look like doorways); _cover fills what is left
    ok = graph_ok & (distance_to_cells(fs, uncovered) <= 0.5 * s) & (fs.clearance() >= cfg.fill_clearance_m)
    rows, cols = np.nonzero(ok)
    if rows.size == 0:
        return
    c, sn = math.cos(theta), math.sin(theta)
    p = fs.centres(rows, cols)
    li = np.round((p[:, 0] * c + p[:, 1] * sn) / s).astype(np.int64)
    lj = np.round((-p[:, 0] * sn + p[:, 1] * c) / s).astype(np.int64)
    del p
    span = int(lj.max() - lj.min()) + 1
    flat = np.unique((li - li.min()) * span + (lj - lj.min()))
    ij = np.stack([flat // span + li.min(), flat % span + lj.min()], axis=1)
    u, v = ij[:, 0] * s, ij[:, 1] * s
    pts = np.stack([u * c - v * sn, u * sn + v * c], axis=1)
    r, k = fs.cell_of(pts)
    inside = ok[r, k] & (b.walls.clearances(np.concatenate([pts, pts], axis=1), 5.0) >= max(cfg.clearance_m, cfg.fill_clearance_m))
    ij, pts = ij[inside], pts[inside]
    if not len(pts):
        return
    n_old = len(b.xy)
    ids = {(int(i), int(j)): b.node(q) for (i, j), q in zip(ij, pts, strict=True)}
    need = cfg.clearance_m + _ROUNDING_M
    pairs = [(a, ids[(i + di, j + dj)]) for (i, j), a in ids.items() for di, dj in ((1, 0), (0, 1)) if (i + di, j + dj) in ids]
    if pairs:
        xy = np.asarray(b.xy)
        pa = np.array(pairs)
        cl = b.walls.clearances(np.concatenate([xy[pa[:, 0]], xy[pa[:, 1]]], axis=1), 5.0)
        for (a, q), cv in zip(pairs, cl, strict=True):
            if cv >= need:
                b.edge(a, q, float(cv))
    xy = np.asarray(b.xy)
    old = xy[:n_old]
    new = np.arange(n_old, len(xy))
    linked = np.zeros(len(xy), dtype=bool)
    if n_old:
        for i in new:
            d = np.hypot(old[:, 0] - xy[i, 0], old[:, 1] - xy[i, 1])
            j = int(np.argmin(d))
            if d[j] <= s and b.clear(xy[i], old[j]) >= need:
                b.chain(int(i), j, b.clear(xy[i], old[j]))
                linked[i] = True
    # lattice pieces: link each to the old graph by its shortest clear link
    ij_e = np.array([k for k in b.edges if k[0] >= n_old and k[1] >= n_old], dtype=np.int64).reshape(-1, 2) - n_old
    comp = graph_components(len(new), ij_e)
    region = fs.region_at(xy)
    old_regions = set(region[:n_old].tolist())
    for cpt in np.unique(comp):
        members = new[comp == cpt]
        if linked[members].any() or not n_old:
            continue
        d = np.hypot(xy[members, None, 0] - old[None, :, 0], xy[members, None, 1] - old[None, :, 1])
        order = np.argsort(d, axis=None)[:64]
        done = False
        for flat in order:
            mi, oj = np.unravel_index(flat, d.shape)
            if d[mi, oj] > 4.0 * cfg.cover_radius_m:
                break
            cv = b.clear(xy[members[mi]], old[oj])
            if cv >= need:
                b.chain(int(members[mi]), int(oj), cv)
                done = True
                break
        if not done and region[members[0]] in old_regions:
            for key in [k for k in b.edges if k[0] in set(members.tolist())]:
                del b.edges[key]


def _connect(b: _Builder, added: list[int], cfg: GraphBuildConfig) -> None:
    """Join each new node to the nearest node it sees clearly and to the new nodes around
    it (a mesh across wide halls); a new node that can join nothing stays alone and is
    dropped at the end."""
    need = cfg.clearance_m + _ROUNDING_M
    xy = np.asarray(b.xy)
    reach = 4.0 * cfg.cover_radius_m
    is_new = np.zeros(len(xy), dtype=bool)
    is_new[added] = True
    for i in added:
        d = np.hypot(xy[:, 0] - xy[i, 0], xy[:, 1] - xy[i, 1])
        cand = np.flatnonzero((d <= reach) & (d > 1e-6))
        cand = cand[np.argsort(d[cand])]
        joined_old = False
        for j in cand:
            if is_new[j]:
                if d[j] > 1.25 * cfg.cover_spacing_m:
                    continue
            elif joined_old:
                continue
            c = b.clear(xy[i], xy[j])
            if c >= need:
                b.chain(i, int(j), c)
                joined_old = joined_old or not is_new[j]
