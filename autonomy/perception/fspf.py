"""Fast Sampling Plane Filtering (FSPF): BV2012, Section III, Algorithm 1, Table I.

FSPF samples a depth image instead of processing all of it: a pixel d0 anywhere, two
more (d1, d2) within eta pixels of it; the plane through their 3D points p0, p1, p2;
a search window sized to show a plane of size S at their mean depth; ``l`` random
samples in that window tested against the plane (|r . (p - p0)| < epsilon). When more
than ``alpha_in * l`` are inliers, the neighbourhood is a local plane: its points go to
P, with the least-squares normal of the inliers in R; otherwise its points go to O, the
outliers. Sampling stops at ``n_max`` plane points or ``k_max`` neighbourhoods.

Readings of the garbled text (the PDF's formulas did not survive extraction):

- Line 13: r = (p1 - p0) x (p2 - p0) / ||(p1 - p0) x (p2 - p0)||.
- Lines 14-16: z_bar = (p0z + p1z + p2z) / 3, and the window is the image size of a
  plane of size S at depth z_bar: w' = S * fx / z_bar and h' = S * fy / z_bar pixels
  (the paper writes this with w, h and the fields of view; fx = w / (2 tan(f_h / 2))).
- Line 17: the "RANSAC" in the window tests the ``l`` local samples against the plane
  hypothesis (p0, r); its inliers get the least-squares (SVD) refit normal.
- On acceptance the three seed points join P with the inliers and the window's other
  samples join O; on rejection all of the neighbourhood's samples join O. So P u O is
  the full sampled cloud the obstacle avoidance uses (Section V).

Random numbers come from an explicit xorshift64* stream seeded per frame, so the numba
kernel and the numpy reference (:func:`fspf_reference`) draw identical samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.rng import MASK64, randint, seed_u64
from autonomy.perception.camera import CameraIntrinsics, CameraMount


@dataclass(frozen=True)
class FSPFConfig:
    """FSPF parameters; defaults are Table I of BV2012."""

    n_max: int = 2000
    """n_max: maximum total number of plane-filtered points."""
    k_max: int = 20000
    """k_max: maximum number of neighbourhoods to sample."""
    l: int = 80  # noqa: E741 - the paper's symbol
    """l: number of local samples in a neighbourhood's window."""
    eta_px: int = 60
    """eta: neighbourhood (pixels) around d0 for d1 and d2."""
    plane_size_m: float = 0.5
    """S: plane size in world space for the local sample window."""
    epsilon_m: float = 0.02
    """epsilon: maximum plane offset error for inliers."""
    alpha_in: float = 0.8
    """alpha_in: minimum inlier fraction to accept a local plane."""
    max_redraws: int = 8
    """How often an invalid (0-depth) pixel is redrawn before the sample is given up."""
    o_max: int = 20000
    """Capacity of the outlier list O (further outliers are dropped)."""
    max_vertical_normal_angle_rad: float = math.radians(60.0)
    """2D projection: points whose normal is within this angle of vertical are dropped."""

    def __post_init__(self) -> None:
        for name in ("n_max", "k_max", "l", "eta_px", "o_max"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise InputError(f"fspf.{name}: expected an integer >= 1, got {v!r}")
        if not self.max_redraws >= 0:
            raise InputError(f"fspf.max_redraws: expected an integer >= 0, got {self.max_redraws!r}")
        for name in ("plane_size_m", "epsilon_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"fspf.{name}: expected a positive number, got {v!r}")
        if not 0.0 < self.alpha_in <= 1.0:
            raise InputError(f"fspf.alpha_in: expected a fraction in (0, 1], got {self.alpha_in!r}")
        if not 0.0 <= self.max_vertical_normal_angle_rad <= math.pi / 2:
            raise InputError("fspf.max_vertical_normal_angle_rad: expected an angle in [0, pi/2]")


@dataclass(frozen=True)
class FSPFResult:
    """FSPF output for one frame (robot frame unless built without a mount)."""

    points: np.ndarray
    """P: plane-filtered points (n, 3)."""
    normals: np.ndarray
    """R: unit normal of each plane point's local plane (n, 3), facing the camera."""
    outliers: np.ndarray
    """O: sampled points that belong to no local plane (m, 3)."""
    plane_ids: np.ndarray
    """Index of the neighbourhood (local plane) each point of P came from (n,)."""
    neighbourhoods: int = 0
    """k: neighbourhoods sampled."""
    planes: int = 0
    """Neighbourhoods accepted as local planes."""
    _proj: dict = field(default_factory=dict, repr=False, compare=False)

    def projected(self, max_vertical_normal_angle_rad: float = math.radians(60.0)) -> tuple[np.ndarray, np.ndarray]:
        """2D points and unit 2D normals in the floor plane (BV2012, IV-B).

        Points whose normal is within the given angle of vertical (floor, ceiling, table
        tops) are dropped; the rest are down-projected to (x, y) with their normals.
        """
        key = float(max_vertical_normal_angle_rad)
        if key not in self._proj:
            self._proj[key] = project_to_floor(self.points, self.normals, key)
        return self._proj[key]


def project_to_floor(points: np.ndarray, normals: np.ndarray, max_vertical_angle_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Down-project plane points with near-horizontal normals: (k, 2) points, (k, 2) unit normals."""
    if len(points) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2))
    nz = np.abs(normals[:, 2])
    keep = nz < math.cos(max_vertical_angle_rad)
    n2 = normals[keep, :2]
    norm = np.hypot(n2[:, 0], n2[:, 1])
    ok = norm > 1e-9
    return np.ascontiguousarray(points[keep][ok, :2]), n2[ok] / norm[ok, None]


# -- random stream: autonomy.common.rng (shared with the plane kernels) ---------------------


# -- the kernel -------------------------------------------------------------------------


@numba.njit(cache=True, inline="always")
def _dot3(u, v):  # pragma: no cover - numba
    """Dot product without BLAS (numba's np.dot needs SciPy)."""
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


@numba.njit(cache=True)
def smallest_eigvec3(a):  # pragma: no cover - numba
    """Unit eigenvector of the smallest eigenvalue of a symmetric 3 x 3 matrix.

    Closed form (no LAPACK): eigenvalues by the trigonometric method for symmetric 3 x 3
    matrices (Smith 1961), eigenvector as the largest cross product of two rows of
    A - lambda I (those rows span the plane orthogonal to the eigenvector).
    """
    # Eigenvectors do not depend on scale: normalise so tiny or huge entries neither
    # underflow into subnormals nor overflow.
    s = 0.0
    for i in range(3):
        for j in range(3):
            s = max(s, abs(a[i, j]))
    out = np.zeros(3)
    if s == 0.0 or not math.isfinite(s):
        out[2] = 1.0
        return out
    a00, a01, a02, a11, a12, a22 = a[0, 0] / s, a[0, 1] / s, a[0, 2] / s, a[1, 1] / s, a[1, 2] / s, a[2, 2] / s
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    p2 = (a00 - q) ** 2 + (a11 - q) ** 2 + (a22 - q) ** 2 + 2.0 * p1
    if p2 <= 1e-30:  # a multiple of the identity: any direction
        out[2] = 1.0
        return out
    p = math.sqrt(p2 / 6.0)
    b00, b11, b22 = (a00 - q) / p, (a11 - q) / p, (a22 - q) / p
    b01, b02, b12 = a01 / p, a02 / p, a12 / p
    r = (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)) / 2.0
    r = min(1.0, max(-1.0, r))
    phi = math.acos(r) / 3.0
    lam = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)  # the smallest eigenvalue
    r0 = np.array([a00 - lam, a01, a02])
    r1 = np.array([a01, a11 - lam, a12])
    r2 = np.array([a02, a12, a22 - lam])
    best = -1.0
    for u, v in ((r0, r1), (r0, r2), (r1, r2)):
        c = np.array([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]])
        n2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
        if n2 > best:
            best = n2
            out[:] = c
    n0, n1, n2 = _dot3(r0, r0), _dot3(r1, r1), _dot3(r2, r2)
    if best <= 1e-18 * (n0 + n1 + n2) ** 2:
        # The two smallest eigenvalues are equal (rank-1 A - lambda I): any vector
        # orthogonal to its largest row is an eigenvector.
        row = r0 if n0 >= n1 and n0 >= n2 else (r1 if n1 >= n2 else r2)
        t = np.array([1.0, 0.0, 0.0]) if abs(row[0]) < 0.9 * math.sqrt(_dot3(row, row)) else np.array([0.0, 1.0, 0.0])
        out[:] = np.array([row[1] * t[2] - row[2] * t[1], row[2] * t[0] - row[0] * t[2], row[0] * t[1] - row[1] * t[0]])
        best = _dot3(out, out)
    return out / math.sqrt(best)


@numba.njit(cache=True)
def _draw_valid(depth, state, v0, u0, half_v, half_u, max_redraws, out):  # pragma: no cover
    """Draw a pixel within (half_v, half_u) of (v0, u0) with valid depth; False if none."""
    h, w = depth.shape
    for _ in range(max_redraws + 1):
        v = v0 + randint(state, -half_v, half_v)
        u = u0 + randint(state, -half_u, half_u)
        if v < 0 or v >= h or u < 0 or u >= w:
            continue
        z = depth[v, u]
        if z > 0.0:
            out[0] = v
            out[1] = u
            return True
    return False


@numba.njit(cache=True)
def _fspf_kernel(
    depth, fx, fy, cx, cy, n_max, k_max, l, eta,  # noqa: E741 - the paper's symbol l
    plane_size, eps, alpha_in, max_redraws, o_max, seed_state,
    rot, trans, out_p, out_r, out_id, out_o, stats,
):  # pragma: no cover - numba
    h, w = depth.shape
    state = np.empty(1, dtype=np.uint64)
    state[0] = seed_state
    pix = np.empty(2, dtype=np.int64)
    local = np.empty((l, 3))
    seeds = np.empty((3, 3))
    inl = np.empty(l, dtype=np.bool_)
    n = 0
    m = 0
    k = 0
    planes = 0
    need = alpha_in * l
    while n < n_max and k < k_max:
        k += 1
        # Lines 9-11: d0 anywhere (valid), d1 and d2 within eta of d0.
        if not _draw_valid(depth, state, (h - 1) // 2, (w - 1) // 2, (h - 1) // 2 + 1, (w - 1) // 2 + 1, max_redraws, pix):
            continue
        v0, u0 = pix[0], pix[1]
        ok = True
        for j in range(3):
            if j > 0:
                if not _draw_valid(depth, state, v0, u0, eta, eta, max_redraws, pix):
                    ok = False
                    break
            else:
                pix[0] = v0
                pix[1] = u0
            z = depth[pix[0], pix[1]]
            seeds[j, 0] = (pix[1] - cx) * z / fx
            seeds[j, 1] = (pix[0] - cy) * z / fy
            seeds[j, 2] = z
        if not ok:
            continue
        # Line 13: plane normal.
        ax, ay, az = seeds[1, 0] - seeds[0, 0], seeds[1, 1] - seeds[0, 1], seeds[1, 2] - seeds[0, 2]
        bx, by, bz = seeds[2, 0] - seeds[0, 0], seeds[2, 1] - seeds[0, 1], seeds[2, 2] - seeds[0, 2]
        rx, ry, rz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        rn = math.sqrt(rx * rx + ry * ry + rz * rz)
        if rn < 1e-12:
            continue  # collinear or repeated samples: no plane hypothesis
        rx, ry, rz = rx / rn, ry / rn, rz / rn
        # Lines 14-16: window of a plane of size S at the mean depth.
        zbar = (seeds[0, 2] + seeds[1, 2] + seeds[2, 2]) / 3.0
        half_u = max(1, int(plane_size * fx / zbar / 2.0))
        half_v = max(1, int(plane_size * fy / zbar / 2.0))
        # Line 17: l local samples in the window, tested against the plane (p0, r).
        cnt = 0
        ninl = 0
        for _ in range(l):
            if not _draw_valid(depth, state, v0, u0, half_v, half_u, max_redraws, pix):
                continue
            z = depth[pix[0], pix[1]]
            px = (pix[1] - cx) * z / fx
            py = (pix[0] - cy) * z / fy
            local[cnt, 0] = px
            local[cnt, 1] = py
            local[cnt, 2] = z
            d = rx * (px - seeds[0, 0]) + ry * (py - seeds[0, 1]) + rz * (z - seeds[0, 2])
            inl[cnt] = abs(d) < eps
            if inl[cnt]:
                ninl += 1
            cnt += 1
        if ninl > need:
            # Least-squares normal over the inliers and the seeds.
            c0 = seeds[0, 0] + seeds[1, 0] + seeds[2, 0]
            c1 = seeds[0, 1] + seeds[1, 1] + seeds[2, 1]
            c2 = seeds[0, 2] + seeds[1, 2] + seeds[2, 2]
            for i in range(cnt):
                if inl[i]:
                    c0 += local[i, 0]
                    c1 += local[i, 1]
                    c2 += local[i, 2]
            tot = ninl + 3
            c0 /= tot
            c1 /= tot
            c2 /= tot
            cov = np.zeros((3, 3))
            for j in range(3 + cnt):
                if j < 3:
                    qx, qy, qz = seeds[j, 0] - c0, seeds[j, 1] - c1, seeds[j, 2] - c2
                else:
                    if not inl[j - 3]:
                        continue
                    qx, qy, qz = local[j - 3, 0] - c0, local[j - 3, 1] - c1, local[j - 3, 2] - c2
                cov[0, 0] += qx * qx
                cov[0, 1] += qx * qy
                cov[0, 2] += qx * qz
                cov[1, 1] += qy * qy
                cov[1, 2] += qy * qz
                cov[2, 2] += qz * qz
            cov[1, 0] = cov[0, 1]
            cov[2, 0] = cov[0, 2]
            cov[2, 1] = cov[1, 2]
            ev = smallest_eigvec3(cov)
            nx, ny, nz = ev[0], ev[1], ev[2]
            if nx * c0 + ny * c1 + nz * c2 > 0.0:  # face the camera
                nx, ny, nz = -nx, -ny, -nz
            # Normal in the robot frame.
            gx = rot[0, 0] * nx + rot[0, 1] * ny + rot[0, 2] * nz
            gy = rot[1, 0] * nx + rot[1, 1] * ny + rot[1, 2] * nz
            gz = rot[2, 0] * nx + rot[2, 1] * ny + rot[2, 2] * nz
            for j in range(3 + cnt):
                if j < 3:
                    qx, qy, qz = seeds[j, 0], seeds[j, 1], seeds[j, 2]
                    to_p = True
                else:
                    qx, qy, qz = local[j - 3, 0], local[j - 3, 1], local[j - 3, 2]
                    to_p = inl[j - 3]
                wx = rot[0, 0] * qx + rot[0, 1] * qy + rot[0, 2] * qz + trans[0]
                wy = rot[1, 0] * qx + rot[1, 1] * qy + rot[1, 2] * qz + trans[1]
                wz = rot[2, 0] * qx + rot[2, 1] * qy + rot[2, 2] * qz + trans[2]
                if to_p:
                    out_p[n, 0] = wx
                    out_p[n, 1] = wy
                    out_p[n, 2] = wz
                    out_r[n, 0] = gx
                    out_r[n, 1] = gy
                    out_r[n, 2] = gz
                    out_id[n] = planes
                    n += 1
                elif m < o_max:
                    out_o[m, 0] = wx
                    out_o[m, 1] = wy
                    out_o[m, 2] = wz
                    m += 1
            planes += 1
        else:
            for j in range(3 + cnt):
                if m >= o_max:
                    break
                if j < 3:
                    qx, qy, qz = seeds[j, 0], seeds[j, 1], seeds[j, 2]
                else:
                    qx, qy, qz = local[j - 3, 0], local[j - 3, 1], local[j - 3, 2]
                out_o[m, 0] = rot[0, 0] * qx + rot[0, 1] * qy + rot[0, 2] * qz + trans[0]
                out_o[m, 1] = rot[1, 0] * qx + rot[1, 1] * qy + rot[1, 2] * qz + trans[1]
                out_o[m, 2] = rot[2, 0] * qx + rot[2, 1] * qy + rot[2, 2] * qz + trans[2]
                m += 1
    stats[0] = n
    stats[1] = m
    stats[2] = k
    stats[3] = planes


def fspf(
    depth: np.ndarray,
    intr: CameraIntrinsics,
    cfg: FSPFConfig = FSPFConfig(),
    seed: int = 0,
    mount: CameraMount | None = CameraMount(),
) -> FSPFResult:
    """Run FSPF on one depth image (float32 metres, 0 = invalid); seeded, deterministic.

    Points and normals are returned in the robot frame through ``mount``, or in the
    camera optical frame when ``mount`` is None.
    """
    depth = np.ascontiguousarray(depth, dtype=np.float32)
    if depth.ndim != 2 or depth.shape != (intr.height, intr.width):
        raise InputError(f"fspf: depth image shape {depth.shape} does not match the camera's {(intr.height, intr.width)}")
    if mount is None:
        rot, trans = np.eye(3), np.zeros(3)
    else:
        rot, trans = mount.rotation(), mount.translation()
    cap = cfg.n_max + cfg.l + 3
    out_p = np.empty((cap, 3))
    out_r = np.empty((cap, 3))
    out_id = np.empty(cap, dtype=np.int32)
    out_o = np.empty((cfg.o_max, 3))
    stats = np.zeros(4, dtype=np.int64)
    if depth.size and (depth > 0).any():
        _fspf_kernel(
            depth, float(intr.fx), float(intr.fy), float(intr.cx), float(intr.cy), cfg.n_max, cfg.k_max, cfg.l,
            cfg.eta_px, float(cfg.plane_size_m), float(cfg.epsilon_m), float(cfg.alpha_in), cfg.max_redraws,
            cfg.o_max, np.uint64(seed_u64(seed)), rot, trans, out_p, out_r, out_id, out_o, stats,
        )
    n, m, k, planes = (int(v) for v in stats)
    return FSPFResult(
        points=out_p[:n].copy(),
        normals=out_r[:n].copy(),
        outliers=out_o[:m].copy(),
        plane_ids=out_id[:n].copy(),
        neighbourhoods=k,
        planes=planes,
    )


# -- slow reference ---------------------------------------------------------------------


class _PyStream:
    """The kernel's xorshift64* stream in plain Python."""

    def __init__(self, seed: int) -> None:
        self.x = seed_u64(seed)

    def randint(self, lo: int, hi: int) -> int:
        x = self.x
        x ^= x >> 12
        x ^= (x << 25) & MASK64
        x ^= x >> 27
        self.x = x
        r = ((x * 2685821657736338717) & MASK64) >> 11
        return lo + r % (hi - lo + 1)


def fspf_reference(depth: np.ndarray, intr: CameraIntrinsics, cfg: FSPFConfig = FSPFConfig(), seed: int = 0) -> list[tuple[bool, int]]:
    """Algorithm 1 in plain numpy/Python, camera frame; for tests.

    Returns, for every neighbourhood that got a plane hypothesis, (accepted, inliers).
    """
    h, w = depth.shape
    rs = _PyStream(seed)

    def draw(v0: int, u0: int, hv: int, hu: int) -> tuple[int, int] | None:
        for _ in range(cfg.max_redraws + 1):
            v, u = v0 + rs.randint(-hv, hv), u0 + rs.randint(-hu, hu)
            if 0 <= v < h and 0 <= u < w and depth[v, u] > 0:
                return v, u
        return None

    def point(v: int, u: int) -> np.ndarray:
        z = float(depth[v, u])
        return np.array([(u - intr.cx) * z / intr.fx, (v - intr.cy) * z / intr.fy, z])

    decisions: list[tuple[bool, int]] = []
    n = k = 0
    while n < cfg.n_max and k < cfg.k_max:
        k += 1
        d0 = draw((h - 1) // 2, (w - 1) // 2, (h - 1) // 2 + 1, (w - 1) // 2 + 1)
        if d0 is None:
            continue
        d1 = draw(*d0, cfg.eta_px, cfg.eta_px)
        if d1 is None:
            continue
        d2 = draw(*d0, cfg.eta_px, cfg.eta_px)
        if d2 is None:
            continue
        p0, p1, p2 = point(*d0), point(*d1), point(*d2)
        r = np.cross(p1 - p0, p2 - p0)
        if np.linalg.norm(r) < 1e-12:
            continue
        r /= np.linalg.norm(r)
        zbar = (p0[2] + p1[2] + p2[2]) / 3
        hu = max(1, int(cfg.plane_size_m * intr.fx / zbar / 2))
        hv = max(1, int(cfg.plane_size_m * intr.fy / zbar / 2))
        inliers = 0
        for _ in range(cfg.l):
            d = draw(*d0, hv, hu)
            if d is None:
                continue
            if abs(r @ (point(*d) - p0)) < cfg.epsilon_m:
                inliers += 1
        accepted = inliers > cfg.alpha_in * cfg.l
        decisions.append((accepted, inliers))
        if accepted:
            n += inliers + 3
    return decisions
