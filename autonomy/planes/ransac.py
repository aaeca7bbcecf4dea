"""Multi-plane RANSAC (PlaneMap, Section II-B2).

For up to ``max_planes`` planes, on the points no earlier plane took:

1. three non-collinear random points give a plane in Hessian normal form (Eq. 2-3);
2. points within ``distance_threshold_m`` (1 cm) of it are its inliers;
3. repeat until a hypothesis has ``inliers_stop`` (50,000) inliers or ``max_iterations``
   (500) hypotheses were tried, keeping the best;
4. refine the best ``refit_iterations`` times by least squares over its inliers (the
   SVD of Eq. 5, in closed form); the points within the threshold of the refined plane
   are its inliers, the plane is their least-squares fit, and they are removed: the
   search goes on with the rest (the "outlier point cloud"). ``refit_iterations = 0``
   is the paper's procedure exactly (inliers of the best hypothesis, fitted once).

It stops early when fewer than ``min_points`` points remain or the best plane has fewer
than ``min_plane_points`` inliers (the paper's "threshold", value ours).

Speed: scoring 500 hypotheses against every remaining point of a 640 x 480 frame costs
~150 M point tests. By default each search scores its hypotheses on a random sample of
``score_sample`` remaining points (drawn once per search, with replacement) and scales
the count to the remaining cloud for the 50,000-inlier stop; the refinements use that
sample's inliers too. The final inliers are taken from all points in one pass that also
sums their moments for the fit. ``score_sample = 0`` scores (and refines) on every
point, the paper's basic RANSAC.
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


@dataclass(frozen=True)
class RansacConfig:
    """Multi-plane RANSAC parameters; defaults from PlaneMap, Section II-B2."""

    distance_threshold_m: float = 0.01
    """Point-to-plane distance below which a point is an inlier (1 cm)."""
    inliers_stop: int = 50_000
    """A hypothesis with this many inliers ends the search (50,000)."""
    max_iterations: int = 500
    """Most hypotheses tried per plane (500)."""
    max_planes: int = 8
    """Most planes per cloud (8)."""
    min_points: int = 1000
    """Stop when fewer points than this remain (the paper's unnamed threshold; ours)."""
    min_plane_points: int = 1000
    """Smallest accepted plane, in inliers (ours)."""
    score_sample: int = 2048
    """Points each search scores hypotheses on; 0 = all remaining points (the paper)."""
    refit_iterations: int = 2
    """Least-squares refinements of the best hypothesis before its inliers are taken (0 = the paper)."""
    min_triangle_m2: float = 1e-6
    """Twice the area of a sample triangle below which its points count as collinear."""
    boundary_column_m: float = 0.01
    """Column width of the boundary hull (its accuracy); 0 = no boundaries."""
    boundary_max_points: int = 50_000
    """The boundary hull uses at most this many of a plane's inliers (every k-th)."""

    def __post_init__(self) -> None:
        require_positive(self, "ransac.", "distance_threshold_m", "min_triangle_m2")
        require_int(self, "ransac.", "inliers_stop", "max_iterations", "max_planes", "min_points", "min_plane_points", "boundary_max_points")
        require_int(self, "ransac.", "score_sample", "refit_iterations", minimum=0)
        if not (math.isfinite(self.boundary_column_m) and self.boundary_column_m >= 0):
            raise InputError(f"ransac.boundary_column_m: expected a number >= 0, got {self.boundary_column_m!r}")


@numba.njit(cache=True)
def _search(pts, idx, n, sample, n_sample, thresh, stop_count, max_iter, min_cross, state):  # pragma: no cover
    """One RANSAC search over ``idx[:n]``: (normal, rho, iterations, best sample count).

    Hypotheses are scored on ``sample[:n_sample]`` (point indices); a count of -1 means
    no non-collinear triple was drawn.
    """
    best_n = np.zeros(3)
    best_rho = 0.0
    best = -1
    scale = n / max(n_sample, 1)
    ft = np.float32(thresh)
    it = 0
    while it < max_iter:
        it += 1
        i0 = idx[randbelow(state, n)]
        i1 = idx[randbelow(state, n)]
        i2 = idx[randbelow(state, n)]
        if i0 == i1 or i0 == i2 or i1 == i2:
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
        if norm < min_cross:
            continue
        nx /= norm
        ny /= norm
        nz /= norm
        rho = nx * pts[i0, 0] + ny * pts[i0, 1] + nz * pts[i0, 2]
        fx, fy, fz, fr = np.float32(nx), np.float32(ny), np.float32(nz), np.float32(rho)
        count = 0
        for k in range(n_sample):
            j = sample[k]
            d = pts[j, 0] * fx + pts[j, 1] * fy + pts[j, 2] * fz - fr
            if abs(d) < ft:
                count += 1
        if count > best:
            best = count
            best_n[0], best_n[1], best_n[2] = nx, ny, nz
            best_rho = rho
            if count * scale >= stop_count:
                break
    return best_n, best_rho, it, best


def ransac_planes(points: np.ndarray, cfg: RansacConfig = RansacConfig(), seed: int = 0) -> PlaneDetection:
    """Detect up to ``cfg.max_planes`` planes in an (N, 3) cloud (metres), seeded.

    Points are best given in a sensor-centred frame (then rho >= 0 is the distance from
    the sensor). Too few points give no planes, not an error.
    """
    t_start = time.perf_counter()
    pts = as_cloud(points)
    n_all = len(pts)
    labels = np.full(n_all, -1, dtype=np.int32)
    idx = np.arange(n_all, dtype=np.int64)
    buf = np.empty(n_all, dtype=np.int64)
    state = seed_state(seed)
    n = n_all
    planes: list[Plane] = []
    plane_ms: list[float] = []
    draws: list[int] = []
    t_prev = t_start
    while len(planes) < cfg.max_planes and n >= max(cfg.min_points, 3):
        sampled = 0 < cfg.score_sample < n
        if sampled:
            sample = np.empty(cfg.score_sample, dtype=np.int64)
            draw_sample(idx, n, state, sample)
        else:
            sample = idx[:n]
        normal, rho, iters, best = _search(
            pts, idx, n, sample, len(sample), cfg.distance_threshold_m, float(cfg.inliers_stop),
            cfg.max_iterations, cfg.min_triangle_m2, state,
        )
        if best < 0:
            break
        normal, rho = refit_plane(pts, sample, normal, rho, cfg.distance_threshold_m, cfg.refit_iterations)
        k = len(planes)
        m, rest, mom = take_inliers(pts, idx, n, normal[0], normal[1], normal[2], rho, cfg.distance_threshold_m, buf, labels, k)
        inl = buf[:m]
        if m < cfg.min_plane_points:
            labels[inl] = -1
            break
        n = rest
        planes.append(make_plane(pts, inl, m, mom, normal, rho, cfg.boundary_column_m, cfg.boundary_max_points))
        t = time.perf_counter()
        plane_ms.append((t - t_prev) * 1e3)
        draws.append(int(iters))
        t_prev = t
    return PlaneDetection(tuple(planes), labels, tuple(plane_ms), (time.perf_counter() - t_start) * 1e3, tuple(draws))
