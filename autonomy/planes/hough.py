"""Randomized Hough transform for planes (PlaneMap, Section II-B1) with a sparse accumulator.

The paper's loop, for up to ``max_planes`` planes while enough points remain:

1. pick a random point and two more from a small circular region around it (here: the
   points of its hashed voxel cell that lie within ``region_radius_m``);
2. the plane through the three, oriented so rho >= 0, becomes one vote in the
   (rho, theta, phi) accumulator of Eq. 1 — rho in 1 cm steps up to 5 m, theta (from
   the frame's z axis) and phi (azimuth) in 1 degree steps;
3. when a cell reaches ``vote_threshold`` votes and is a local maximum of its 26
   neighbours, it is a plane: refined by least squares (first over the points within
   ``refit_band_m`` of the peak's plane, then within ``distance_threshold_m``, on a
   random sample of ``refit_sample`` remaining points), its points — all those within
   ``distance_threshold_m`` — are removed and fitted once more, their boundary is
   computed and the accumulator is reset. The peak's plane is the mean of the votes
   within 1.5 cells of the peak cell, which removes the cell quantisation.

The accumulator. The paper's dense array of 500 x 180 x 360 = 32.4 M cells took 125 MB,
and resetting it dominated the run time. A search for one plane casts a few thousand
votes into at most that many cells, so here the accumulator is an open-addressing hash
table (int64 cell key -> int32 count, linear probing, ``accumulator_capacity`` slots)
plus the list of slots touched since the last reset (and a log of the voted planes, for
the peak's sub-cell mean). Same cells, same resolution; a vote is one hash probe, a
reset clears only the touched slots. With the default 2^16 slots and 20,000 triples it
takes 1.5 MB; see :func:`accumulator_nbytes` and docs/mapping.md for the costs.

The accumulator's pole is the z axis of the points' frame. On the paper's grid every
theta ring has 360 phi cells, so near the pole cells shrink to slivers and the votes
for a plane facing +z scatter over many of them. ``equal_area = True`` (the default,
ours, after Borrmann et al. 2011's "ball" accumulator) gives the ring at theta
ceil(360 sin theta) phi cells: 1 x 1 degree cells at the equator as in the paper,
cells 0.78-1 degree of arc wide everywhere else, 36 % fewer cells. Either way, give points
in a sensor-centred frame with z up: walls then fall on the equator, where both grids
are the paper's 1 x 1 degree.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numba
import numpy as np

from autonomy.common.errors import InputError, require_int, require_positive
from autonomy.common.rng import randbelow, seed_state
from autonomy.planes.geometry import (
    Plane,
    PlaneDetection,
    as_cloud,
    draw_sample,
    make_plane,
    refit_plane,
    take_inliers,
)

_EMPTY = np.int64(-1)


@dataclass(frozen=True)
class HoughConfig:
    """Randomized Hough transform parameters; PlaneMap, Section II-B1 where it gives them."""

    rho_step_m: float = 0.01
    """Accumulator rho resolution (1 cm)."""
    rho_max_m: float = 5.0
    """Largest rho in the accumulator (500 cm); planes farther away get no votes."""
    angle_step_deg: float = 1.0
    """Accumulator theta and phi resolution (1 degree)."""
    region_radius_m: float = 0.15
    """Radius of the "small circular region" the three points come from (ours)."""
    min_point_distance_m: float = 0.03
    """The second and third point are at least this far from the first (ours)."""
    min_region_points: int = 30
    """Regions (voxel buckets) with fewer live points cast no votes: a handful of points
    would vote for the same few triples again and again (ours)."""
    vote_threshold: int = 25
    """Votes in a local-maximum cell that make it a plane (ours)."""
    distance_threshold_m: float = 0.01
    """Points within this distance of a found plane are its points (1 cm, as RANSAC's)."""
    refit_band_m: float = 0.02
    """The first refinement takes the points within this band of the peak's plane (ours)."""
    refit_iterations: int = 2
    """Least-squares refinements before the plane's points are taken (the first within the band)."""
    refit_sample: int = 8192
    """The refinements use this many random remaining points (0 = all of them) (ours)."""
    max_planes: int = 8
    """Most planes per cloud (8)."""
    min_points: int = 1000
    """Stop when fewer points than this remain (the paper's MinPoints; value ours)."""
    min_plane_points: int = 1000
    """A peak with fewer points is dropped (its points are still removed) (ours)."""
    max_triples: int = 20_000
    """Triples voted per plane before giving up on finding another one (ours)."""
    equal_area: bool = True
    """Widen phi cells towards the poles to ~1 x 1 degree of arc (ours; false = the paper's grid)."""
    accumulator_capacity: int = 1 << 16
    """Hash-table slots (a power of two, at least 2 x max_triples)."""
    boundary_column_m: float = 0.01
    """Column width of the boundary hull (its accuracy); 0 = no boundaries."""
    boundary_max_points: int = 50_000
    """The boundary hull uses at most this many of a plane's inliers (every k-th)."""

    def __post_init__(self) -> None:
        require_positive(self, "hough.", "rho_step_m", "rho_max_m", "angle_step_deg", "region_radius_m", "distance_threshold_m", "refit_band_m")
        if not 0 <= self.min_point_distance_m < self.region_radius_m:
            raise InputError("hough.min_point_distance_m: expected a number in [0, region_radius_m)")
        require_int(self, "hough.", "min_region_points", "vote_threshold", "max_planes", "min_points", "min_plane_points", "max_triples", "boundary_max_points")
        require_int(self, "hough.", "refit_iterations", "refit_sample", minimum=0)
        cap = self.accumulator_capacity
        if not (isinstance(cap, int) and cap >= 2 * self.max_triples and cap & (cap - 1) == 0):
            raise InputError(
                f"hough.accumulator_capacity: expected a power of two >= 2 x max_triples = {2 * self.max_triples}, got {cap!r}"
            )
        if not (180.0 / self.angle_step_deg) <= 3600:
            raise InputError("hough.angle_step_deg: expected a step of at least 0.05 degrees")
        if not (math.isfinite(self.boundary_column_m) and self.boundary_column_m >= 0):
            raise InputError(f"hough.boundary_column_m: expected a number >= 0, got {self.boundary_column_m!r}")

    @property
    def shape(self) -> tuple[int, int, int]:
        """Accumulator cells along (rho, theta, phi): (500, 180, 360) by default."""
        return (
            math.ceil(self.rho_max_m / self.rho_step_m - 1e-9),
            math.ceil(180.0 / self.angle_step_deg - 1e-9),
            math.ceil(360.0 / self.angle_step_deg - 1e-9),
        )


def dense_accumulator_nbytes(cfg: HoughConfig = HoughConfig(), bytes_per_cell: int = 4) -> int:
    """Size of a dense accumulator of these cells (paper's grid: 32.4 M int32 cells, 130 MB = 124 MiB)."""
    return cfg.shape[0] * int(ring_cells(cfg)[1][-1]) * bytes_per_cell


def accumulator_nbytes(cfg: HoughConfig = HoughConfig()) -> int:
    """Memory of the sparse accumulator: keys (8 B) and counts (4 B) per slot, and per
    triple a touched-slot entry (4 B) and the logged vote (32 B)."""
    return cfg.accumulator_capacity * 12 + cfg.max_triples * 36


# -- the sparse accumulator --------------------------------------------------------------


@numba.njit(cache=True, inline="always")
def _slot(key, mask):  # pragma: no cover - numba
    h = (np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(20)
    return np.int64(h & np.uint64(mask))


@numba.njit(cache=True)
def _acc_add(keys, counts, touched, n_touched, key):  # pragma: no cover - numba
    """One vote for ``key``; returns (new count, new n_touched)."""
    mask = len(keys) - 1
    s = _slot(key, mask)
    while True:
        k = keys[s]
        if k == key:
            counts[s] += 1
            return counts[s], n_touched
        if k == -1:
            keys[s] = key
            counts[s] = 1
            touched[n_touched] = s
            return 1, n_touched + 1
        s = (s + 1) & mask


@numba.njit(cache=True)
def _acc_get(keys, counts, key):  # pragma: no cover - numba
    mask = len(keys) - 1
    s = _slot(key, mask)
    while True:
        k = keys[s]
        if k == key:
            return counts[s]
        if k == -1:
            return 0
        s = (s + 1) & mask


@numba.njit(cache=True)
def _acc_reset(keys, counts, touched, n_touched):  # pragma: no cover - numba
    for t in range(n_touched):
        s = touched[t]
        keys[s] = -1
        counts[s] = 0


@numba.njit(cache=True)
def _is_local_max(keys, counts, ri, ti, pj, count, nr, ring_n, ring_off):  # pragma: no cover - numba
    """True if no neighbour of cell (ri, ti, pj) has more votes.

    Neighbours: the cells above and below in rho, the two beside it in phi (wrapping),
    and in the theta rings on either side the cell under the same phi and its two phi
    neighbours; a ring past a pole folds over (phi + pi).
    """
    nt = len(ring_n)
    per_rho = ring_off[nt]
    two_pi = 2.0 * math.pi
    phi_c = (pj + 0.5) * two_pi / ring_n[ti]
    for dr in range(-1, 2):
        r = ri + dr
        if r < 0 or r >= nr:
            continue
        for dt in range(-1, 2):
            t = ti + dt
            ph = phi_c
            if t < 0:  # across the pole at theta = 0
                t = -t - 1
                ph += math.pi
            elif t >= nt:
                t = 2 * nt - t - 1
                ph += math.pi
            m = ring_n[t]
            j0 = np.int64(ph / (two_pi / m))
            for dp in range(-1, 2):
                if dr == 0 and dt == 0 and dp == 0:
                    continue
                j = (j0 + dp) % m
                if _acc_get(keys, counts, r * per_rho + ring_off[t] + j) > count:
                    return False
    return True


def ring_cells(cfg: HoughConfig) -> tuple[np.ndarray, np.ndarray]:
    """Phi cells per theta ring (nt,) and ring offsets (nt + 1,) of the accumulator.

    Uniform: 360 phi cells in every ring (the paper). Equal area: ceil(360 sin theta)
    cells in the ring at theta, so every cell spans about 1 x 1 degree of arc.
    """
    _, nt, nphi = cfg.shape
    if cfg.equal_area:
        mid = (np.arange(nt) + 0.5) * math.radians(cfg.angle_step_deg)
        ring_n = np.maximum(1, np.ceil(nphi * np.sin(np.minimum(mid, math.pi - mid)) - 1e-9)).astype(np.int64)
    else:
        ring_n = np.full(nt, nphi, dtype=np.int64)
    ring_off = np.zeros(nt + 1, dtype=np.int64)
    ring_off[1:] = np.cumsum(ring_n)
    return ring_n, ring_off


# -- the voxel hash the point triples come from -------------------------------------------


@numba.njit(cache=True)
def _build_cells(pts, cell_m, n_buckets):  # pragma: no cover - numba
    """Bucket every point by its hashed voxel (counting sort): (start (B+1,), order (N,)).

    ``order`` lists the points bucket by bucket; bucket b is ``order[start[b]:start[b+1]]``.
    Voxels that hash to the same bucket share it (the region test rejects the strangers).
    """
    n = len(pts)
    bucket = np.empty(n, dtype=np.int32)
    counts = np.zeros(n_buckets + 1, dtype=np.int64)
    inv = 1.0 / cell_m
    off = float(1 << 20)  # shift to positive so truncation is floor (|x| < 2^20 cells)
    mask = np.uint32(n_buckets - 1)
    for i in range(n):
        cx = np.uint32(np.int64(pts[i, 0] * inv + off))
        cy = np.uint32(np.int64(pts[i, 1] * inv + off))
        cz = np.uint32(np.int64(pts[i, 2] * inv + off))
        h = (cx * np.uint32(73856093)) ^ (cy * np.uint32(19349663)) ^ (cz * np.uint32(83492791))
        h = (h * np.uint32(2654435761)) >> np.uint32(8)
        b = np.int32(h & mask)
        bucket[i] = b
        counts[b + 1] += 1
    for b in range(n_buckets):
        counts[b + 1] += counts[b]
    fill = counts[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        b = bucket[i]
        order[fill[b]] = i
        fill[b] += 1
    return counts, order


@numba.njit(cache=True)
def _scatter_labels(order, labels_s, labels):  # pragma: no cover - numba
    for k in range(len(order)):
        labels[order[k]] = labels_s[k]


@numba.njit(cache=True)
def _gather_rows(pts, order):  # pragma: no cover - numba
    out = np.empty((len(order), 3), dtype=pts.dtype)
    for k in range(len(order)):
        i = order[k]
        out[k, 0] = pts[i, 0]
        out[k, 1] = pts[i, 1]
        out[k, 2] = pts[i, 2]
    return out


@numba.njit(cache=True)
def _sorted_buckets(start):  # pragma: no cover - numba
    """Bucket of every position of the bucket-sorted cloud, and each bucket's live length."""
    nb = len(start) - 1
    of = np.empty(start[nb], dtype=np.int64)
    blen = np.empty(nb, dtype=np.int64)
    for b in range(nb):
        blen[b] = start[b + 1] - start[b]
        for k in range(start[b], start[b + 1]):
            of[k] = b
    return of, blen


@numba.njit(cache=True)
def _compact_buckets(start, blen, slots, labels):  # pragma: no cover - numba
    """Drop taken points from every bucket's list of live positions (in place)."""
    for b in range(len(blen)):
        lo = start[b]
        m = 0
        for k in range(lo, lo + blen[b]):
            j = slots[k]
            if labels[j] < 0:
                slots[lo + m] = j
                m += 1
        blen[b] = m


@numba.njit(cache=True)
def _pick_near(pts, i0, b, start, blen, slots, r2max, r2min, state, tries):  # pragma: no cover
    """A live point of bucket ``b`` (i0's) within the region around point i0, or -1."""
    m = blen[b]
    lo = start[b]
    for _ in range(tries):
        j = slots[lo + randbelow(state, m)]
        if j == i0:
            continue
        dx = pts[j, 0] - pts[i0, 0]
        dy = pts[j, 1] - pts[i0, 1]
        dz = pts[j, 2] - pts[i0, 2]
        d2 = dx * dx + dy * dy + dz * dz
        if r2min <= d2 <= r2max:
            return j
    return -1


@numba.njit(cache=True)
def _hough_search(
    pts, idx, n, bucket_of, start, blen, slots, keys, counts, touched, votes,
    r_max, r_min, min_region, rho_step, angle_step_rad, nr, ring_n, ring_off, threshold, max_triples, state,
):  # pragma: no cover - numba
    """Vote random triples until a local-maximum cell reaches the threshold.

    ``pts`` is the bucket-sorted cloud, ``idx[:n]`` its live positions, ``bucket_of``
    the bucket of each position and ``slots`` the buckets' live positions.

    Every vote's plane is logged in ``votes``; a peak's plane is the mean of the votes
    within 1.5 cells of it (sub-cell accuracy, no quantisation). Returns (found, normal
    (3,), rho, triples voted, draws); the accumulator is reset before returning.
    """
    nt = len(ring_n)
    per_rho = ring_off[nt]
    two_pi = 2.0 * math.pi
    r2max = r_max * r_max
    r2min = r_min * r_min
    n_touched = 0
    n_votes = 0
    triples = 0
    draws = 0
    max_draws = 4 * max_triples
    found = False
    fr, ft, fp = -1, -1, -1
    while triples < max_triples and draws < max_draws:
        draws += 1
        i0 = idx[randbelow(state, n)]
        b = bucket_of[i0]
        if blen[b] < min_region:
            continue
        i1 = _pick_near(pts, i0, b, start, blen, slots, r2max, r2min, state, 4)
        if i1 < 0:
            continue
        i2 = _pick_near(pts, i0, b, start, blen, slots, r2max, r2min, state, 4)
        if i2 < 0 or i2 == i1:
            continue
        ax = np.float64(pts[i1, 0]) - pts[i0, 0]
        ay = np.float64(pts[i1, 1]) - pts[i0, 1]
        az = np.float64(pts[i1, 2]) - pts[i0, 2]
        bx = np.float64(pts[i2, 0]) - pts[i0, 0]
        by = np.float64(pts[i2, 1]) - pts[i0, 1]
        bz = np.float64(pts[i2, 2]) - pts[i0, 2]
        nx = ay * bz - az * by
        ny = az * bx - ax * bz
        nz = ax * by - ay * bx
        norm = math.sqrt(nx * nx + ny * ny + nz * nz)
        # Near-collinear triples (twice the area below (r_min / 2)^2) carry no plane.
        if norm < 0.25 * r2min + 1e-12:
            continue
        nx /= norm
        ny /= norm
        nz /= norm
        rho = nx * pts[i0, 0] + ny * pts[i0, 1] + nz * pts[i0, 2]
        if rho < 0.0:
            rho = -rho
            nx, ny, nz = -nx, -ny, -nz
        triples += 1
        ri = np.int64(rho / rho_step)
        if ri >= nr:
            continue
        theta = math.acos(min(1.0, max(-1.0, nz)))
        phi = math.atan2(ny, nx) + math.pi
        ti = min(np.int64(theta / angle_step_rad), nt - 1)
        m = ring_n[ti]
        pi = np.int64(phi / (two_pi / m)) % m
        key = ri * per_rho + ring_off[ti] + pi
        votes[n_votes, 0] = nx
        votes[n_votes, 1] = ny
        votes[n_votes, 2] = nz
        votes[n_votes, 3] = rho
        n_votes += 1
        c, n_touched = _acc_add(keys, counts, touched, n_touched, key)
        if c >= threshold and _is_local_max(keys, counts, ri, ti, pi, c, nr, ring_n, ring_off):
            found = True
            fr, ft, fp = ri, ti, pi
            break
    _acc_reset(keys, counts, touched, n_touched)
    mean = np.zeros(4)
    if found:
        theta = (ft + 0.5) * angle_step_rad
        phi = (fp + 0.5) * two_pi / ring_n[ft] - math.pi
        cx, cy, cz = math.cos(phi) * math.sin(theta), math.sin(phi) * math.sin(theta), math.cos(theta)
        crho = (fr + 0.5) * rho_step
        cos_lim = math.cos(1.5 * angle_step_rad)
        k = 0
        for v in range(n_votes):
            if votes[v, 0] * cx + votes[v, 1] * cy + votes[v, 2] * cz >= cos_lim and abs(votes[v, 3] - crho) <= 1.5 * rho_step:
                mean += votes[v]
                k += 1
        norm = math.sqrt(mean[0] ** 2 + mean[1] ** 2 + mean[2] ** 2)
        if k == 0 or norm == 0.0:
            mean[0], mean[1], mean[2], mean[3] = cx, cy, cz, crho
        else:
            mean[:3] /= norm
            mean[3] /= k
    return found, mean[:3].copy(), mean[3], triples, draws


class SparseAccumulator:
    """The hash-table accumulator's arrays (reusable across calls; never holds votes between them)."""

    def __init__(self, cfg: HoughConfig) -> None:
        self.keys = np.full(cfg.accumulator_capacity, _EMPTY, dtype=np.int64)
        self.counts = np.zeros(cfg.accumulator_capacity, dtype=np.int32)
        self.touched = np.empty(cfg.max_triples, dtype=np.int32)
        self.votes = np.empty((cfg.max_triples, 4), dtype=np.float64)

    @property
    def nbytes(self) -> int:
        return int(self.keys.nbytes + self.counts.nbytes + self.touched.nbytes + self.votes.nbytes)


def hough_planes(
    points: np.ndarray,
    cfg: HoughConfig = HoughConfig(),
    seed: int = 0,
    accumulator: SparseAccumulator | None = None,
) -> PlaneDetection:
    """Detect up to ``cfg.max_planes`` planes in an (N, 3) cloud (metres), seeded.

    Points should be in a sensor-centred frame (rho is limited to ``rho_max_m``) with z
    up (see the module docstring). Too few points give no planes, not an error.
    """
    t_start = time.perf_counter()
    pts = as_cloud(points)
    n_all = len(pts)
    labels = np.full(n_all, -1, dtype=np.int32)
    planes: list[Plane] = []
    plane_ms: list[float] = []
    draws: list[int] = []
    if n_all < max(cfg.min_points, 3):
        return PlaneDetection((), labels, (), (time.perf_counter() - t_start) * 1e3, ())
    acc = accumulator if accumulator is not None else SparseAccumulator(cfg)
    if len(acc.keys) != cfg.accumulator_capacity or len(acc.touched) < cfg.max_triples or len(acc.votes) < cfg.max_triples:
        raise InputError("hough_planes: the accumulator was made for another HoughConfig")
    # Work on a copy sorted by voxel bucket: a region's points sit together in memory.
    n_buckets = 1 << max(10, int(math.ceil(math.log2(max(n_all, 1) / 16 + 1))))
    start, order = _build_cells(pts, 2.0 * cfg.region_radius_m, n_buckets)
    pts = _gather_rows(pts, order)
    bucket_of, blen = _sorted_buckets(start)
    slots = np.arange(n_all, dtype=np.int64)
    labels_s = np.full(n_all, -1, dtype=np.int32)
    idx = np.arange(n_all, dtype=np.int64)
    buf = np.empty(n_all, dtype=np.int64)
    state = seed_state(seed)
    nr = cfg.shape[0]
    ring_n, ring_off = ring_cells(cfg)
    ang = math.radians(cfg.angle_step_deg)
    n = n_all
    t_prev = t_start
    dropped = 0
    while len(planes) < cfg.max_planes and n >= max(cfg.min_points, 3) and dropped <= 2 * cfg.max_planes:
        found, normal, rho, triples, _ = _hough_search(
            pts, idx, n, bucket_of, start, blen, slots, acc.keys, acc.counts, acc.touched, acc.votes,
            cfg.region_radius_m, cfg.min_point_distance_m, cfg.min_region_points, cfg.rho_step_m, ang, nr, ring_n, ring_off,
            cfg.vote_threshold, cfg.max_triples, state,
        )
        if not found:
            break
        if 0 < cfg.refit_sample < n:
            on = np.empty(cfg.refit_sample, dtype=np.int64)
            draw_sample(idx, n, state, on)
        else:
            on = idx[:n]
        normal, rho = refit_plane(pts, on, normal, rho, cfg.distance_threshold_m, cfg.refit_iterations, first_band=cfg.refit_band_m)
        k = len(planes)
        m, n, mom = take_inliers(pts, idx, n, normal[0], normal[1], normal[2], rho, cfg.distance_threshold_m, buf, labels_s, k)
        inl = buf[:m]
        if m >= cfg.min_plane_points:
            planes.append(make_plane(pts, inl, m, mom, normal, rho, cfg.boundary_column_m, cfg.boundary_max_points))
        else:
            # Too small to keep: drop its points so the same peak is not found again.
            labels_s[inl] = np.iinfo(np.int32).max
            dropped += 1
        _compact_buckets(start, blen, slots, labels_s)
        t = time.perf_counter()
        if m >= cfg.min_plane_points:
            plane_ms.append((t - t_prev) * 1e3)
            draws.append(int(triples))
            t_prev = t
    labels_s[labels_s == np.iinfo(np.int32).max] = -1
    _scatter_labels(order, labels_s, labels)
    return PlaneDetection(tuple(planes), labels, tuple(plane_ms), (time.perf_counter() - t_start) * 1e3, tuple(draws))
