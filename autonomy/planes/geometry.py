"""Planes in Hessian normal form, least-squares fits, point clouds from depth images.

A plane is ``n . p = rho`` with a unit normal ``n``. In the frame a plane was detected
in (centred on the sensor), ``rho >= 0``: the normal points away from the sensor, as in
the paper's Hessian form (PlaneMap, Section II-B, Eq. 3-5). Moved to another frame
(:meth:`Plane.transformed`) the normal keeps its direction, so ``rho`` may turn negative.

The paper's spherical parameters (Section II-B1, Eq. 1, Fig. 4): ``theta`` is the angle
between the normal and the frame's z axis (0..180 degrees), ``phi`` the angle of its
projection in the x-y plane from the x axis (-180..180 degrees).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.rng import randbelow
from autonomy.perception.camera import CameraIntrinsics
from autonomy.perception.fspf import smallest_eigvec3
from autonomy.planes.boundary import plane_hull


@dataclass(frozen=True, eq=False)
class Plane:
    """One detected plane: Hessian normal form, support and extent."""

    normal: np.ndarray
    """Unit normal n (3,), pointing away from the sensor it was seen from."""
    rho: float
    """Offset: n . p = rho for points p on the plane (>= 0 in the detection frame)."""
    centroid: np.ndarray
    """Mean of the inlier points (3,): the plane's centre point (Section II-A)."""
    n_points: int
    """Number of inlier points the plane was fitted to."""
    rms_m: float = 0.0
    """Root mean square point-to-plane distance of the inliers."""
    hull: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """Boundary polygon (K, 3): convex hull of the inliers in the plane, in order."""

    def spherical(self) -> tuple[float, float, float]:
        """(rho, theta, phi) of Eq. 1, angles in radians."""
        return plane_spherical(self.normal, self.rho)

    def transformed(self, t: np.ndarray) -> Plane:
        """The plane in another frame: ``t`` is the 4 x 4 transform new_from_old."""
        r, tr = t[:3, :3], t[:3, 3]
        n = r @ self.normal
        c = r @ self.centroid + tr
        hull = self.hull @ r.T + tr if len(self.hull) else self.hull.copy()
        return Plane(n, float(self.rho + n @ tr), c, self.n_points, self.rms_m, hull)

    def distance(self, pts: np.ndarray) -> np.ndarray:
        """Signed distances of points (..., 3) to the plane."""
        return np.asarray(pts) @ self.normal - self.rho

    def to_dict(self) -> dict:
        """JSON-able form."""
        return {
            "normal": [float(v) for v in self.normal],
            "rho": float(self.rho),
            "centroid": [float(v) for v in self.centroid],
            "n_points": int(self.n_points),
            "rms_m": float(self.rms_m),
            "hull": [[float(v) for v in p] for p in self.hull],
        }

    @classmethod
    def from_dict(cls, d: dict, source: str = "plane") -> Plane:
        """Inverse of :meth:`to_dict` (InputError naming ``source`` on bad input)."""
        try:
            n = np.asarray(d["normal"], dtype=np.float64)
            c = np.asarray(d["centroid"], dtype=np.float64)
            hull = np.asarray(d.get("hull", []), dtype=np.float64).reshape(-1, 3)
            p = cls(n, float(d["rho"]), c, int(d["n_points"]), float(d.get("rms_m", 0.0)), hull)
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{source}: expected normal, rho, centroid, n_points (and hull): {exc}") from None
        if n.shape != (3,) or c.shape != (3,) or not abs(np.linalg.norm(n) - 1.0) < 1e-6:
            raise InputError(f"{source}: normal must be a unit 3-vector and centroid a 3-vector")
        return p


def plane_spherical(normal: np.ndarray, rho: float) -> tuple[float, float, float]:
    """(rho, theta, phi) of a normal (Eq. 1): theta from +z in [0, pi], phi in (-pi, pi].
    theta is atan2 of the horizontal and vertical parts: acos of the vertical part alone
    loses half the digits near the poles (a normal 1e-9 rad from +z came back as 0)."""
    nx, ny, nz = float(normal[0]), float(normal[1]), float(normal[2])
    return float(rho), math.atan2(math.hypot(nx, ny), nz), math.atan2(ny, nx)


def spherical_normal(theta: float, phi: float) -> np.ndarray:
    """Unit normal of spherical angles (Eq. 1): (cos phi sin theta, sin phi sin theta, cos theta)."""
    return np.array([math.cos(phi) * math.sin(theta), math.sin(phi) * math.sin(theta), math.cos(theta)])


def angle_between_planes_deg(n1: np.ndarray, n2: np.ndarray) -> float:
    """Angle between two planes in degrees, in [0, 90] (sign of the normals ignored)."""
    c = abs(float(np.dot(n1, n2))) / (float(np.linalg.norm(n1)) * float(np.linalg.norm(n2)))
    return math.degrees(math.acos(min(1.0, c)))


# -- numba helpers shared by the detectors ---------------------------------------------


@numba.njit(cache=True)
def fit_plane_indexed(pts, idx, n):  # pragma: no cover - numba
    """Least-squares plane through ``pts[idx[:n]]``: (normal, rho, centroid, rms).

    The normal is the right singular vector of the smallest singular value of the
    centred points (Section II-B2, Eq. 5), i.e. the smallest eigenvector of their
    scatter matrix, by the closed form of :func:`autonomy.perception.fspf.smallest_eigvec3`.
    The normal is oriented so that rho >= 0.
    """
    c = np.zeros(3)
    for k in range(n):
        i = idx[k]
        c[0] += pts[i, 0]
        c[1] += pts[i, 1]
        c[2] += pts[i, 2]
    c /= max(n, 1)
    a = np.zeros((3, 3))
    for k in range(n):
        i = idx[k]
        x = pts[i, 0] - c[0]
        y = pts[i, 1] - c[1]
        z = pts[i, 2] - c[2]
        a[0, 0] += x * x
        a[0, 1] += x * y
        a[0, 2] += x * z
        a[1, 1] += y * y
        a[1, 2] += y * z
        a[2, 2] += z * z
    a[1, 0] = a[0, 1]
    a[2, 0] = a[0, 2]
    a[2, 1] = a[1, 2]
    nrm = smallest_eigvec3(a)
    rho = nrm[0] * c[0] + nrm[1] * c[1] + nrm[2] * c[2]
    if rho < 0.0:
        nrm = -nrm
        rho = -rho
    ev = nrm[0] * (a[0, 0] * nrm[0] + a[0, 1] * nrm[1] + a[0, 2] * nrm[2])
    ev += nrm[1] * (a[1, 0] * nrm[0] + a[1, 1] * nrm[1] + a[1, 2] * nrm[2])
    ev += nrm[2] * (a[2, 0] * nrm[0] + a[2, 1] * nrm[1] + a[2, 2] * nrm[2])
    rms = math.sqrt(max(ev, 0.0) / max(n, 1))
    return nrm, rho, c, rms


@numba.njit(cache=True, inline="always")
def _add_moments(s, x, y, z):  # pragma: no cover - numba
    """Add one point (relative to the foot point) to the moments (x, y, z, xx, xy, xz, yy, yz, zz)."""
    s[0] += x
    s[1] += y
    s[2] += z
    s[3] += x * x
    s[4] += x * y
    s[5] += x * z
    s[6] += y * y
    s[7] += y * z
    s[8] += z * z


@numba.njit(cache=True)
def inlier_moments(pts, idx, n, nx, ny, nz, rho, thresh):  # pragma: no cover - numba
    """Count and moments of the entries of ``idx[:n]`` within ``thresh`` of a plane.

    Returns (m, s) with s = (sum x, y, z, xx, xy, xz, yy, yz, zz) of the points relative
    to the plane's foot point rho * n (a shift that keeps the sums well conditioned).
    """
    m = 0
    ox, oy, oz = rho * nx, rho * ny, rho * nz
    fx, fy, fz, fr, ft = np.float32(nx), np.float32(ny), np.float32(nz), np.float32(rho), np.float32(thresh)
    s = np.zeros(9)
    for k in range(n):
        i = idx[k]
        px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
        d = px * fx + py * fy + pz * fz - fr
        if abs(d) < ft:
            _add_moments(s, px - ox, py - oy, pz - oz)
            m += 1
    return m, s


@numba.njit(cache=True)
def fit_from_moments(m, s, nx, ny, nz, rho):  # pragma: no cover - numba
    """Least-squares plane from :func:`inlier_moments` output: (normal, rho >= 0, centroid, rms)."""
    ox, oy, oz = rho * nx, rho * ny, rho * nz
    inv = 1.0 / max(m, 1)
    mx, my, mz = s[0] * inv, s[1] * inv, s[2] * inv
    a = np.empty((3, 3))
    a[0, 0] = s[3] * inv - mx * mx
    a[0, 1] = s[4] * inv - mx * my
    a[0, 2] = s[5] * inv - mx * mz
    a[1, 1] = s[6] * inv - my * my
    a[1, 2] = s[7] * inv - my * mz
    a[2, 2] = s[8] * inv - mz * mz
    a[1, 0] = a[0, 1]
    a[2, 0] = a[0, 2]
    a[2, 1] = a[1, 2]
    nrm = smallest_eigvec3(a)
    c = np.array([mx + ox, my + oy, mz + oz])
    r = nrm[0] * c[0] + nrm[1] * c[1] + nrm[2] * c[2]
    if r < 0.0:
        nrm = -nrm
        r = -r
    ev = 0.0
    for i in range(3):
        for j in range(3):
            ev += nrm[i] * a[i, j] * nrm[j]
    return nrm, r, c, math.sqrt(max(ev, 0.0))


@numba.njit(cache=True)
def take_inliers(pts, idx, n, nx, ny, nz, rho, thresh, out, labels, label):  # pragma: no cover - numba
    """Move the entries of ``idx[:n]`` within ``thresh`` of a plane to ``out`` and label them.

    One pass: ``idx`` is compacted in place to the rest, ``labels[i] = label`` for every
    inlier i, and the inliers' moments are summed as in :func:`inlier_moments`.
    Returns (inliers, rest, moments).
    """
    m = 0
    r = 0
    ox, oy, oz = rho * nx, rho * ny, rho * nz
    fx, fy, fz, fr, ft = np.float32(nx), np.float32(ny), np.float32(nz), np.float32(rho), np.float32(thresh)
    s = np.zeros(9)
    for k in range(n):
        i = idx[k]
        px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
        d = px * fx + py * fy + pz * fz - fr
        if abs(d) < ft:
            out[m] = i
            m += 1
            labels[i] = label
            _add_moments(s, px - ox, py - oy, pz - oz)
        else:
            idx[r] = i
            r += 1
    return m, r, s


@numba.njit(cache=True)
def draw_sample(idx, n, state, out):  # pragma: no cover - numba
    """Fill ``out`` with entries of ``idx[:n]`` drawn uniformly with replacement."""
    for k in range(len(out)):
        out[k] = idx[randbelow(state, n)]


def fit_plane(points: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, float]:
    """Least-squares plane of an (n, 3) array (n >= 3): (normal, rho >= 0, centroid, rms)."""
    pts = np.ascontiguousarray(points, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3:
        raise InputError(f"fit_plane: expected an (n >= 3, 3) array of points, got shape {pts.shape}")
    idx = np.arange(len(pts), dtype=np.int64)
    n, rho, c, rms = fit_plane_indexed(pts, idx, len(pts))
    return n, float(rho), c, float(rms)


def as_cloud(points: np.ndarray, name: str = "points") -> np.ndarray:
    """Validate an (N, 3) point array; float32, C-contiguous, finite rows only."""
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"{name}: expected an (N, 3) array of points, got shape {pts.shape}")
    pts = np.ascontiguousarray(pts, dtype=np.float32)
    if len(pts) and not np.isfinite(pts).all():
        pts = np.ascontiguousarray(pts[np.isfinite(pts).all(axis=1)])
    return pts


@numba.njit(cache=True)
def _depth_to_cloud(depth, fx, fy, cx, cy, stride, r, max_range, out, pix):  # pragma: no cover
    h, w = depth.shape
    n = 0
    for v in range(0, h, stride):
        for u in range(0, w, stride):
            z = depth[v, u]
            if z <= 0.0 or z > max_range:
                continue
            x = (u - cx) * z / fx
            y = (v - cy) * z / fy
            out[n, 0] = r[0, 0] * x + r[0, 1] * y + r[0, 2] * z
            out[n, 1] = r[1, 0] * x + r[1, 1] * y + r[1, 2] * z
            out[n, 2] = r[2, 0] * x + r[2, 1] * y + r[2, 2] * z
            pix[n] = v * w + u
            n += 1
    return n


def depth_to_cloud(
    depth: np.ndarray,
    intr: CameraIntrinsics,
    rotation: np.ndarray | None = None,
    *,
    stride: int = 1,
    max_range_m: float = math.inf,
) -> tuple[np.ndarray, np.ndarray]:
    """Valid pixels of a depth image as points: ((N, 3) float32, (N,) flat pixel index).

    Points are ``rotation @ p_optical``: pass the rotation from the optical frame to a
    sensor-centred frame of your choice (for the Hough accumulator, one with z up; e.g.
    the rotation part of world_from_camera). Every ``stride``-th pixel in both directions.
    """
    d = np.ascontiguousarray(depth, dtype=np.float32)
    if d.shape != (intr.height, intr.width):
        raise InputError(f"depth image shape {d.shape} does not match the camera's {(intr.height, intr.width)}")
    if not (isinstance(stride, int) and stride >= 1):
        raise InputError(f"stride: expected an integer >= 1, got {stride!r}")
    r = np.eye(3) if rotation is None else np.ascontiguousarray(rotation, dtype=np.float64)
    if r.shape != (3, 3):
        raise InputError(f"rotation: expected a 3 x 3 matrix, got shape {r.shape}")
    cap = ((intr.height + stride - 1) // stride) * ((intr.width + stride - 1) // stride)
    out = np.empty((cap, 3), dtype=np.float32)
    pix = np.empty(cap, dtype=np.int32)
    n = _depth_to_cloud(d, intr.fx, intr.fy, intr.cx, intr.cy, stride, r, float(max_range_m), out, pix)
    return out[:n], pix[:n]


@dataclass(frozen=True, eq=False)
class PlaneDetection:
    """What a multi-plane detector found in one cloud."""

    planes: tuple[Plane, ...]
    """Detected planes, in the order found."""
    labels: np.ndarray
    """(N,) int32: index of the plane each input point was assigned to, -1 for none."""
    plane_ms: tuple[float, ...]
    """Wall time spent finding each plane (refits and boundary included)."""
    total_ms: float
    """Wall time of the whole call."""
    draws: tuple[int, ...]
    """Per plane: RANSAC iterations, or Hough point triples voted."""

    @property
    def first_plane_ms(self) -> float:
        """Time to the first plane (Section IV-C); NaN if none was found."""
        return self.plane_ms[0] if self.plane_ms else float("nan")


def refit_plane(
    pts: np.ndarray, on: np.ndarray, normal, rho: float, thresh: float, rounds: int, first_band: float | None = None
) -> tuple[np.ndarray, float]:
    """``rounds`` least-squares refits of a plane over its inliers among the points ``on``
    (within ``thresh``; the first round within ``first_band`` if given, for a coarse
    first estimate such as a Hough cell's)."""
    band = thresh if first_band is None else max(first_band, thresh)
    for _ in range(rounds):
        m, mom = inlier_moments(pts, on, len(on), normal[0], normal[1], normal[2], rho, band)
        if m < 3:
            break
        normal, rho, _, _ = fit_from_moments(m, mom, normal[0], normal[1], normal[2], rho)
        band = thresh
    return normal, rho


def make_plane(pts: np.ndarray, inl: np.ndarray, m: int, mom, normal, rho: float, boundary_column_m: float, boundary_max_points: int) -> Plane:
    """The final plane from its ``m`` inliers ``inl`` and their moments (from
    :func:`take_inliers`): least-squares fit, centroid, rms and boundary polygon."""
    normal, rho, c, rms = fit_from_moments(m, mom, normal[0], normal[1], normal[2], rho)
    hull = plane_hull(pts, inl, normal, rho, c, boundary_column_m, boundary_max_points) if boundary_column_m > 0 else np.zeros((0, 3))
    return Plane(np.array(normal, dtype=np.float64), float(rho), np.array(c), int(m), float(rms), hull)
