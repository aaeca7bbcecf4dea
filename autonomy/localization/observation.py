"""Observation models on scene lines: projected 3D point cloud (BV2012, IV-B) and laser.

For each 2D plane-filtered point p_i (robot frame) and a pose x = (t, theta), the point in
the world is q_i = R(theta) p_i + t. Following Section IV-B:

1. the scene line l_i hit by the ray from t towards q_i is found;
2. points without such a line are discarded;
3. points whose normal differs from the line's normal by more than theta_max are
   discarded;
4. d_i is the perpendicular distance of q_i from the (extended) line l_i;
5. p(y | x) = prod_i exp(-d_i^2 / (2 f sigma^2))   (Eq. 1, read from the garbled PDF:
   sigma the standard deviation of one distance measurement, f >= 1 the discount for
   the correlation between rays).

The gradient (Eq. 2) of ln p(y | x) = -sum d_i^2 / (2 f sigma^2) follows from rigid
translation and rotation of the point cloud: d d_i / d t = n_i and
d d_i / d theta = n_i . J (q_i - t), with J the 90 degree rotation.

Our additions (not in the paper): points farther than ``max_distance_m`` from their
line are also discarded as unexplained (people, furniture), and correspondences (which
line each point belongs to) are computed once per frame at a shared pose and reused by
every particle near it (:func:`correspond`), since they hardly differ between nearby
particles; the distances and gradients are then evaluated per particle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import wrap_angle_nb


@dataclass(frozen=True)
class ObservationConfig:
    """Parameters of the point-cloud (and laser) observation model."""

    sigma_m: float = 0.05
    """sigma: standard deviation of one distance measurement (Eq. 1)."""
    correlation_f: float = 10.0
    """f: discount for the correlation between rays, f >= 1 (Eq. 1)."""
    theta_max_rad: float = math.radians(35.0)
    """theta_max: maximum angle between a point's normal and its line's normal."""
    max_distance_m: float = 0.5
    """Points farther than this from their line are discarded (ours; the paper keeps every
    point whose ray hits a line); CGR widens it with its uncertainty (cgr.gate_sigmas)."""
    min_points: int = 10
    """Fewer usable points than this: no observation update (odometry only)."""

    def __post_init__(self) -> None:
        if not (self.sigma_m > 0 and math.isfinite(self.sigma_m)):
            raise InputError(f"observation.sigma_m: expected a positive number, got {self.sigma_m!r}")
        if not self.correlation_f >= 1.0:
            raise InputError(f"observation.correlation_f: expected a number >= 1, got {self.correlation_f!r}")
        if not 0 < self.theta_max_rad <= math.pi:
            raise InputError("observation.theta_max_rad: expected an angle in (0, pi]")
        if not self.max_distance_m > 0:
            raise InputError("observation.max_distance_m: expected a positive number")
        if self.min_points < 1:
            raise InputError("observation.min_points: expected an integer >= 1")

    @property
    def inv_two_f_sigma2(self) -> float:
        return 1.0 / (2.0 * self.correlation_f * self.sigma_m**2)


@numba.njit(cache=True)
def line_frames(lines, ox, oy):  # pragma: no cover - numba
    """Unit normals (facing the point (ox, oy)) and offsets c = n . a of each line (M, 3)."""
    m = lines.shape[0]
    out = np.empty((m, 3))
    for j in range(m):
        ax, ay, bx, by = lines[j, 0], lines[j, 1], lines[j, 2], lines[j, 3]
        dx, dy = bx - ax, by - ay
        L = math.sqrt(dx * dx + dy * dy)
        if L <= 0.0:
            out[j, 0] = 0.0
            out[j, 1] = 0.0
            out[j, 2] = 0.0
            continue
        nx, ny = -dy / L, dx / L
        if nx * (ox - ax) + ny * (oy - ay) < 0.0:
            nx, ny = -nx, -ny
        out[j, 0] = nx
        out[j, 1] = ny
        out[j, 2] = nx * ax + ny * ay
    return out


@numba.njit(cache=True)
def correspond(lines, pose, pts, nrm, use_normals, cos_theta_max, max_dist, out_idx):  # pragma: no cover
    """Line index for each point (-1: discarded) at ``pose``; returns the count kept.

    The line is the first one hit by the ray from the robot's location through the
    point (rule 1); rules 2-3 and the distance gate discard the rest.
    """
    x, y, th = pose[0], pose[1], pose[2]
    c, s = math.cos(th), math.sin(th)
    frames = line_frames(lines, x, y)
    m = lines.shape[0]
    kept = 0
    for i in range(pts.shape[0]):
        qx = c * pts[i, 0] - s * pts[i, 1]
        qy = s * pts[i, 0] + c * pts[i, 1]
        # Ray from (x, y) along (qx, qy) (q - t in the world frame).
        best = -1
        best_t = np.inf
        for j in range(m):
            ax, ay = lines[j, 0] - x, lines[j, 1] - y
            ex, ey = lines[j, 2] - lines[j, 0], lines[j, 3] - lines[j, 1]
            den = qx * ey - qy * ex
            if den == 0.0:
                continue
            t = (ax * ey - ay * ex) / den
            u = (ax * qy - ay * qx) / den
            if t > 0.0 and -1e-9 <= u <= 1.0 + 1e-9 and t < best_t:
                best_t = t
                best = j
        if best < 0:
            out_idx[i] = -1
            continue
        nx, ny = frames[best, 0], frames[best, 1]
        if use_normals:
            wx = c * nrm[i, 0] - s * nrm[i, 1]
            wy = s * nrm[i, 0] + c * nrm[i, 1]
            if wx * nx + wy * ny < cos_theta_max:
                out_idx[i] = -1
                continue
        d = nx * (qx + x) + ny * (qy + y) - frames[best, 2]
        if abs(d) > max_dist:
            out_idx[i] = -1
            continue
        # The gate is on the distance to the segment, not to its infinite line: a point
        # short of a small segment (a pillar's face seen past a table) or off its end (a
        # box beside a pillar) must not match it.
        ex, ey = lines[best, 2] - lines[best, 0], lines[best, 3] - lines[best, 1]
        el = math.sqrt(ex * ex + ey * ey)
        if el > 0.0:
            along = ((qx + x - lines[best, 0]) * ex + (qy + y - lines[best, 1]) * ey) / el
            off = -along if along < 0.0 else (along - el if along > el else 0.0)
            if d * d + off * off > max_dist * max_dist:
                out_idx[i] = -1
                continue
        out_idx[i] = best
        kept += 1
    return kept


def associate(lines: np.ndarray, pose: np.ndarray, points_2d: np.ndarray, normals_2d: np.ndarray, cfg: ObservationConfig) -> np.ndarray:
    """For each observation point, the index of the scene line ``lines`` (K, 4) it is
    associated with at ``pose`` (-1: none), as CGR's observation model associates them
    (BV2012 Eq. 1, :func:`correspond`). For viewers: one association pass."""
    pts = np.ascontiguousarray(points_2d, dtype=np.float64).reshape(-1, 2)
    idx = np.full(len(pts), -1, dtype=np.int64)
    if len(lines) and len(pts):
        nrm = np.ascontiguousarray(normals_2d, dtype=np.float64).reshape(-1, 2)
        correspond(
            np.ascontiguousarray(lines, dtype=np.float64), np.asarray(pose, dtype=np.float64), pts, nrm, True,
            math.cos(cfg.theta_max_rad), cfg.max_distance_m, idx,
        )
    return idx


@numba.njit(cache=True)
def loglik_grad(frames, idx, pose, pts, inv_2fs2, out):  # pragma: no cover - numba
    """ln p(y | x) (Eq. 1), its gradient (Eq. 2) and the Gauss-Newton curvature at ``pose``.

    ``out`` receives [lnp, g_x, g_y, g_theta, H_xx, H_yy, H_tt, n_used, H_xy, H_xt, H_yt]
    where H = sum J_i^T J_i / (f sigma^2) with J_i = d d_i / d (x, y, theta);
    correspondences ``idx`` are fixed (from :func:`correspond`).
    """
    x, y, th = pose[0], pose[1], pose[2]
    c, s = math.cos(th), math.sin(th)
    lnp = 0.0
    gx = gy = gt = 0.0
    hxx = hyy = htt = hxy = hxt = hyt = 0.0
    n = 0
    k2 = 2.0 * inv_2fs2
    for i in range(pts.shape[0]):
        j = idx[i]
        if j < 0:
            continue
        rx = c * pts[i, 0] - s * pts[i, 1]
        ry = s * pts[i, 0] + c * pts[i, 1]
        nx, ny = frames[j, 0], frames[j, 1]
        d = nx * (rx + x) + ny * (ry + y) - frames[j, 2]
        dth = nx * (-ry) + ny * rx  # n . J (q - t)
        lnp -= d * d * inv_2fs2
        gx -= d * nx * k2
        gy -= d * ny * k2
        gt -= d * dth * k2
        hxx += nx * nx * k2
        hyy += ny * ny * k2
        htt += dth * dth * k2
        hxy += nx * ny * k2
        hxt += nx * dth * k2
        hyt += ny * dth * k2
        n += 1
    out[0] = lnp
    out[1] = gx
    out[2] = gy
    out[3] = gt
    out[4] = hxx
    out[5] = hyy
    out[6] = htt
    out[7] = n
    out[8] = hxy
    out[9] = hxt
    out[10] = hyt


@numba.njit(cache=True)
def robust_weights(frames, idx, pose, pts, scale, out):  # pragma: no cover - numba
    """Cauchy weights w_i = 1 / (1 + (d_i / scale)^2) of the used points at ``pose`` (0 for
    the others) into ``out``; every used point weighs 1 when ``scale`` <= 0.

    Iteratively reweighted least squares with the weights of one pose (ours): the
    refinement's squared distances (Eq. 1) let a few points matched to the wrong line
    outweigh hundreds on the right one. Points seen just past a pillar's corner, matched
    to the pillar's face 0.3-0.5 m in front of them, pulled a sample 0.37 m along a
    corridor in one frame; weighed by their distance at the proposal mean, they barely
    count, while a whole wall the belief is off from keeps its pull (a step along a
    direction all of whose points weigh alike is the same at any weight).
    """
    x, y, th = pose[0], pose[1], pose[2]
    c, s = math.cos(th), math.sin(th)
    for i in range(pts.shape[0]):
        j = idx[i]
        if j < 0:
            out[i] = 0.0
            continue
        if scale <= 0.0:
            out[i] = 1.0
            continue
        rx = c * pts[i, 0] - s * pts[i, 1] + x
        ry = s * pts[i, 0] + c * pts[i, 1] + y
        d = (frames[j, 0] * rx + frames[j, 1] * ry - frames[j, 2]) / scale
        out[i] = 1.0 / (1.0 + d * d)


@numba.njit(cache=True)
def moments(frames, idx, pts, out, weights=None):  # pragma: no cover - numba
    """The 5 x 5 moment matrix M = sum w_i v_i v_i^T of the used points; returns their count.

    With fixed correspondences, d_i = v_i . z where v_i = (n . p_i, n x p_i, n_x, n_y, -c)
    (p_i in the robot frame, n and c of its line) and z = (cos theta, sin theta, t_x,
    t_y, 1). So ln p(y | x) = -k sum w_i d_i^2 = -k z^T M z, its gradient and its
    Gauss-Newton curvature at any pose follow from M alone (:func:`loglik_grad_m`): one
    pass over the points serves every particle that shares the correspondences, and every
    refinement step. ``weights`` (:func:`robust_weights`; None: all 1) scale each point's
    term; M[2, 2] + M[3, 3] is their sum.
    """
    for a in range(5):
        for b in range(5):
            out[a, b] = 0.0
    n = 0
    v = np.empty(5)
    for i in range(pts.shape[0]):
        j = idx[i]
        if j < 0:
            continue
        w = 1.0 if weights is None else weights[i]
        nx, ny = frames[j, 0], frames[j, 1]
        v[0] = nx * pts[i, 0] + ny * pts[i, 1]
        v[1] = ny * pts[i, 0] - nx * pts[i, 1]
        v[2] = nx
        v[3] = ny
        v[4] = -frames[j, 2]
        for a in range(5):
            for b in range(a, 5):
                out[a, b] += w * v[a] * v[b]
        n += 1
    for a in range(5):
        for b in range(a):
            out[a, b] = out[b, a]
    return n


@numba.njit(cache=True)
def moments_lever(m):  # pragma: no cover - numba
    """The (weighted) RMS range of the points behind a moment matrix: M[0, 0] + M[1, 1] is
    sum w |p|^2 and M[2, 2] + M[3, 3] is sum w (:func:`moments`); 0 without points."""
    wsum = m[2, 2] + m[3, 3]
    return math.sqrt((m[0, 0] + m[1, 1]) / wsum) if wsum > 0.0 else 0.0


@numba.njit(cache=True)
def loglik_grad_m(m, n_used, pose, inv_2fs2, out):  # pragma: no cover - numba
    """Same outputs as :func:`loglik_grad`, from the moment matrix (O(25) per pose)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    z = np.array([c, s, pose[0], pose[1], 1.0])
    w = np.array([-s, c, 0.0, 0.0, 0.0])  # d z / d theta
    mz = np.zeros(5)
    mw = np.zeros(5)
    for a in range(5):
        for b in range(5):
            mz[a] += m[a, b] * z[b]
            mw[a] += m[a, b] * w[b]
    zmz = 0.0
    wmz = 0.0
    wmw = 0.0
    for a in range(5):
        zmz += z[a] * mz[a]
        wmz += w[a] * mz[a]
        wmw += w[a] * mw[a]
    k2 = 2.0 * inv_2fs2
    out[0] = -inv_2fs2 * zmz
    out[1] = -k2 * mz[2]
    out[2] = -k2 * mz[3]
    out[3] = -k2 * wmz
    out[4] = k2 * m[2, 2]
    out[5] = k2 * m[3, 3]
    out[6] = k2 * wmw
    out[7] = n_used
    out[8] = k2 * m[2, 3]
    out[9] = k2 * mw[2]
    out[10] = k2 * mw[3]


@numba.njit(cache=True)
def jacobi_eigh3(a, vecs):  # pragma: no cover - numba
    """Eigenvalues (returned, (3,)) and unit eigenvectors (the columns of ``vecs``) of a
    symmetric 3 x 3 matrix by cyclic Jacobi rotations (no LAPACK: numba's eigh needs
    SciPy). Converges quadratically; 12 sweeps reach machine precision. The matrix is
    first scaled by a power of two (exact) to a largest entry in [0.5, 1): the squared
    entries of a matrix of 1e-160 would underflow and read as already diagonal. Each
    entry is scaled on its own (``ldexp``): the factor alone, 2^1038 for a subnormal
    largest entry, is not a finite float."""
    big = 0.0
    for i in range(3):
        for j in range(3):
            big = max(big, abs(a[i, j]))
    e = math.frexp(big)[1] if big > 0.0 and math.isfinite(big) else 0
    b = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            b[i, j] = math.ldexp(a[i, j], -e)
    for i in range(3):
        for j in range(3):
            vecs[i, j] = 1.0 if i == j else 0.0
    for _ in range(12):
        off = b[0, 1] * b[0, 1] + b[0, 2] * b[0, 2] + b[1, 2] * b[1, 2]
        scale = b[0, 0] * b[0, 0] + b[1, 1] * b[1, 1] + b[2, 2] * b[2, 2]
        if off <= 1e-30 * scale or off == 0.0:
            break
        for p in range(2):
            for q in range(p + 1, 3):
                if b[p, q] == 0.0:
                    continue
                theta = (b[q, q] - b[p, p]) / (2.0 * b[p, q])
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(3):  # B <- B J
                    bkp, bkq = b[k, p], b[k, q]
                    b[k, p] = c * bkp - s * bkq
                    b[k, q] = s * bkp + c * bkq
                for k in range(3):  # B <- J^T B
                    bpk, bqk = b[p, k], b[q, k]
                    b[p, k] = c * bpk - s * bqk
                    b[q, k] = s * bpk + c * bqk
                for k in range(3):
                    vkp, vkq = vecs[k, p], vecs[k, q]
                    vecs[k, p] = c * vkp - s * vkq
                    vecs[k, q] = s * vkp + c * vkq
    return np.array([math.ldexp(b[0, 0], e), math.ldexp(b[1, 1], e), math.ldexp(b[2, 2], e)])


@numba.njit(cache=True)
def trusted_directions(frames, idx, pose, pts, lever_m, max_gain, out_proj, weights=None):  # pragma: no cover - numba
    """The pose directions the frame's points pin down, as a projector ``out_proj``
    (3 x 3, pose coordinates); returns how many of the three are trusted.

    Degeneracy-aware update after Zhang and Singh ("On degeneracy of optimization-based
    state estimation problems", ICRA 2016): the Gauss-Newton curvature is decomposed in
    pose coordinates with the heading scaled by the points' RMS range ``lever_m`` (so a
    metre and a radian at that range weigh alike), and a step is taken only along the
    eigen-directions the points constrain. A direction v is trusted when its bias gain
    sum_i |J_i . v| / sum_i (J_i . v)^2 is at most ``max_gain``: a systematic error of b
    in every point's distance to its line (a wall's face a centimetre off its map line,
    a map drawn a few centimetres off) moves the least-squares optimum by at most
    gain * b along v. A single wall has gain 1 across it; two walls 0.84 degrees from
    parallel have gain 68 along them, so a 1 cm bias slides the optimum 0.68 m along a
    corridor, which the refinement would otherwise follow frame by frame. Along an
    untrusted direction the sample keeps its motion-model pose (ours: the criterion;
    Zhang and Singh threshold the eigenvalue). ``max_gain`` <= 0 trusts every direction.
    ``weights`` (:func:`robust_weights`; None: all 1) weigh the points as the refinement does.
    """
    for a in range(3):
        for b in range(3):
            out_proj[a, b] = 1.0 if a == b else 0.0
    if max_gain <= 0.0 or lever_m <= 0.0:
        return 3
    # The Jacobian rows J_i = d d_i / d (x, y, lever theta) of the used points.
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rows = np.empty((pts.shape[0], 3))
    wr = np.empty(pts.shape[0])
    n = 0
    for i in range(pts.shape[0]):
        j = idx[i]
        if j < 0:
            continue
        wr[n] = 1.0 if weights is None else weights[i]
        rx = c * pts[i, 0] - s * pts[i, 1]
        ry = s * pts[i, 0] + c * pts[i, 1]
        nx, ny = frames[j, 0], frames[j, 1]
        rows[n, 0] = nx
        rows[n, 1] = ny
        rows[n, 2] = (nx * (-ry) + ny * rx) / lever_m
        n += 1
    if n == 0:
        return 3
    a3 = np.zeros((3, 3))
    for i in range(n):
        for a in range(3):
            for b in range(3):
                a3[a, b] += wr[i] * rows[i, a] * rows[i, b]
    vecs = np.empty((3, 3))
    jacobi_eigh3(a3, vecs)
    s1 = np.zeros(3)
    s2 = np.zeros(3)
    for i in range(n):
        for k in range(3):
            d = rows[i, 0] * vecs[0, k] + rows[i, 1] * vecs[1, k] + rows[i, 2] * vecs[2, k]
            s1[k] += wr[i] * abs(d)
            s2[k] += wr[i] * d * d
    ps = np.zeros((3, 3))
    trusted = 0
    for k in range(3):
        # s1 <= sqrt(n s2), so a tiny s2 cannot pass unless s1 is tinier still.
        if s2[k] > 0.0 and s1[k] <= max_gain * s2[k]:
            trusted += 1
            for a in range(3):
                for b in range(3):
                    ps[a, b] += vecs[a, k] * vecs[b, k]
    # Back to pose coordinates: u = S^-1 x with S = diag(1, 1, 1 / lever), P = S Ps S^-1.
    for a in range(3):
        for b in range(3):
            sa = 1.0 / lever_m if a == 2 else 1.0
            sb = lever_m if b == 2 else 1.0
            out_proj[a, b] = sa * ps[a, b] * sb
    return trusted


#: The projector that trusts every direction (:func:`trusted_directions` switched off).
ALL_DIRECTIONS = np.eye(3)


@numba.njit(cache=True)
def _gn_step(work, kappa, pose, proj=ALL_DIRECTIONS):  # pragma: no cover - numba
    """pose += kappa P (H + lambda I)^-1 g from a loglik_grad output, P the projector on
    the trusted directions (:func:`trusted_directions`); False if singular."""
    lam = 1e-3 * (work[4] + work[5] + work[6]) / 3.0 + 1e-9
    a, b, cc = work[4] + lam, work[8], work[9]
    d, e = work[5] + lam, work[10]
    f = work[6] + lam
    c00 = d * f - e * e
    c01 = cc * e - b * f
    c02 = b * e - cc * d
    det = a * c00 + b * c01 + cc * c02
    if not det > 0.0:
        return False
    c11 = a * f - cc * cc
    c12 = b * cc - a * e
    c22 = a * d - b * b
    g0, g1, g2 = work[1], work[2], work[3]
    d0 = (c00 * g0 + c01 * g1 + c02 * g2) / det
    d1 = (c01 * g0 + c11 * g1 + c12 * g2) / det
    d2 = (c02 * g0 + c12 * g1 + c22 * g2) / det
    pose[0] += kappa * (proj[0, 0] * d0 + proj[0, 1] * d1 + proj[0, 2] * d2)
    pose[1] += kappa * (proj[1, 0] * d0 + proj[1, 1] * d1 + proj[1, 2] * d2)
    pose[2] += kappa * (proj[2, 0] * d0 + proj[2, 1] * d1 + proj[2, 2] * d2)
    return True


@numba.njit(cache=True)
def _trust_clip(pose, start, lever_m, trust_m):  # pragma: no cover - numba
    """Keep a refined pose within the trust region of its first-stage pose; True if clipped.

    The correspondences are fixed where the refinement starts, and they hold only nearby:
    a point more than the correspondence gate away from its line would have matched
    another line, or none. So the refinement may move the points by at most ``trust_m``,
    a pose change counted as |dt| + lever |dtheta| with ``lever`` the used points' RMS
    range. Without this bound a Gauss-Newton step on a near-degenerate observation (ten
    points of one wall within 30 cm, two of them off it) leapt 1.3 m and 29 degrees in
    one frame, where the paper's plain gradient steps would have crept (ours).
    """
    dx = pose[0] - start[0]
    dy = pose[1] - start[1]
    dth = wrap_angle_nb(pose[2] - start[2])
    d = math.sqrt(dx * dx + dy * dy) + lever_m * abs(dth)
    if d <= trust_m:
        return False
    f = trust_m / d
    pose[0] = start[0] + f * dx
    pose[1] = start[1] + f * dy
    pose[2] = start[2] + f * dth
    return True


#: ``refine_all_m``'s prior information when there is none: the likelihood alone.
NO_PRIOR = np.zeros(3)


@numba.njit(cache=True)
def refine_all_m(
    m, n_used, poses, inv_2fs2, iters, kappa, min_points, out_poses, lnp0, lnpr, trust_m=np.inf, prior_info=NO_PRIOR,
    proj=ALL_DIRECTIONS, centre=NO_PRIOR,
):  # pragma: no cover
    """CGR step 2 for every particle sharing one moment matrix: first-stage and refined
    log-likelihoods and the refined poses.

    Each of the r steps is kappa * (H + lambda I)^-1 g: the gradient preconditioned by the
    damped Gauss-Newton curvature (our reading of "refined using the gradients": a plain
    fixed step zig-zags when x, y and theta are coupled). Along a direction the points do
    not constrain (a featureless corridor) both H and g vanish, so the sample does not
    move. The refined pose stays within ``trust_m`` of the first-stage pose
    (:func:`_trust_clip`).

    ``prior_info`` (1/sigma^2 for x, y, theta) adds a Gaussian prior centred on each
    sample's first-stage pose: the steps then climb ln p(y|x) + ln p(x), and a direction
    the points hardly constrain (one pillar face: its slope trades heading for sideways
    offset) stays where the motion model put the sample instead of leaping along it (ours;
    zeros: the likelihood alone). ``lnpr`` stays the likelihood alone.

    ``proj`` restricts every step to the directions the points pin down
    (:func:`trusted_directions`; the identity: all of them), and the likelihoods are
    read at the sample's pose with its offset from ``centre`` (the pose the
    correspondences were found at) along the other directions removed: a frame that
    does not pin a direction neither moves the samples along it nor weighs them by it,
    so resampling cannot carry the belief towards a biased optimum either.
    """
    work = np.zeros(11)
    lever = moments_lever(m)
    q0 = np.empty(3)
    d = np.empty(3)
    for i in range(poses.shape[0]):
        p = out_poses[i]
        if n_used < min_points:
            p[0] = poses[i, 0]
            p[1] = poses[i, 1]
            p[2] = poses[i, 2]
            lnp0[i] = -np.inf
            lnpr[i] = -np.inf
            continue
        # q0 = p0 + (P - I)(p0 - centre): exactly p0 when every direction is trusted.
        d[0] = poses[i, 0] - centre[0]
        d[1] = poses[i, 1] - centre[1]
        d[2] = wrap_angle_nb(poses[i, 2] - centre[2])
        for a in range(3):
            q0[a] = poses[i, a] + (proj[a, 0] - (1.0 if a == 0 else 0.0)) * d[0] + (
                proj[a, 1] - (1.0 if a == 1 else 0.0)
            ) * d[1] + (proj[a, 2] - (1.0 if a == 2 else 0.0)) * d[2]
            p[a] = q0[a]
        loglik_grad_m(m, n_used, p, inv_2fs2, work)
        lnp0[i] = work[0]
        for _ in range(iters):
            _add_prior(work, p, q0, prior_info)
            if not _gn_step(work, kappa, p, proj):
                break
            clipped = _trust_clip(p, q0, lever, trust_m)
            loglik_grad_m(m, n_used, p, inv_2fs2, work)
            if clipped:
                break
        lnpr[i] = work[0]
        for a in range(3):
            p[a] = p[a] + (poses[i, a] - q0[a])


@numba.njit(cache=True)
def _add_prior(work, pose, centre, info):  # pragma: no cover - numba
    """Add a Gaussian prior's gradient and curvature (diagonal ``info``, centred on
    ``centre``) to a loglik_grad output, in place (the log-likelihood itself unchanged)."""
    dx = pose[0] - centre[0]
    dy = pose[1] - centre[1]
    dth = wrap_angle_nb(pose[2] - centre[2])
    work[1] -= info[0] * dx
    work[2] -= info[1] * dy
    work[3] -= info[2] * dth
    work[4] += info[0]
    work[5] += info[1]
    work[6] += info[2]


def expected_ranges(lines: np.ndarray, pose: np.ndarray, angles: np.ndarray, max_range_m: float = np.inf) -> np.ndarray:
    """Laser ranges a sensor at ``pose`` would measure along ``angles`` (robot frame) on the
    scene lines; 0 where a ray hits nothing within ``max_range_m`` (no return)."""
    from autonomy.maps.raycast import rays_hit

    a = np.asarray(angles, dtype=np.float64) + float(pose[2])
    idx, t = rays_hit(np.ascontiguousarray(lines, dtype=np.float64).reshape(-1, 4), float(pose[0]), float(pose[1]), np.column_stack([np.cos(a), np.sin(a)]))
    return np.where((idx >= 0) & (t < max_range_m), t, 0.0)


def points_from_scan(ranges: np.ndarray, angles: np.ndarray, max_range_m: float) -> np.ndarray:
    """Laser ranges (0 or beyond max range = no return) to 2D points in the sensor frame."""
    r = np.asarray(ranges, dtype=np.float64)
    ok = (r > 0) & (r < max_range_m) & np.isfinite(r)
    a = np.asarray(angles, dtype=np.float64)[ok]
    return np.column_stack([r[ok] * np.cos(a), r[ok] * np.sin(a)])


class PointCloudModel:
    """Eq. 1-2 for one pose: correspondences, likelihood and gradient (tests, tools).

    ``normals`` None gives the laser variant (no normal test): the scan's end points are
    matched to the scene lines hit by their rays, as the simulated-laser baselines need.
    """

    def __init__(self, cfg: ObservationConfig = ObservationConfig()) -> None:
        self.cfg = cfg

    def evaluate(
        self, lines: np.ndarray, pose: np.ndarray, points: np.ndarray, normals: np.ndarray | None
    ) -> tuple[float, np.ndarray, int]:
        """(ln p(y | x), gradient (3,), points used) at ``pose``."""
        lines = np.ascontiguousarray(lines, dtype=np.float64).reshape(-1, 4)
        pose = np.asarray(pose, dtype=np.float64)
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        use_n = normals is not None
        nrm = np.ascontiguousarray(normals if use_n else np.zeros_like(pts), dtype=np.float64).reshape(-1, 2)
        idx = np.empty(len(pts), dtype=np.int64)
        correspond(lines, pose, pts, nrm, use_n, math.cos(self.cfg.theta_max_rad), self.cfg.max_distance_m, idx)
        out = np.zeros(11)
        loglik_grad(line_frames(lines, pose[0], pose[1]), idx, pose, pts, self.cfg.inv_two_f_sigma2, out)
        return float(out[0]), out[1:4].copy(), int(out[7])
