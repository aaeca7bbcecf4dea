"""Numba kernels of the clean image's geometry: incidence angles from normals, lateral
sigmas, and the projector-shadow scan."""

from __future__ import annotations

import math

import numba
import numpy as np

from sim.simulator.kinect_noise.config import THETA_MAX_RAD

_F32 = np.float32
# Abramowitz & Stegun 4.4.46: acos(x) = sqrt(1 - x) * poly(x), |error| <= 2e-8 on [0, 1].
_A0, _A1, _A2, _A3 = (
    _F32(1.5707963050),
    _F32(-0.2145988016),
    _F32(0.0889789874),
    _F32(-0.0501743046),
)
_A4, _A5, _A6, _A7 = (
    _F32(0.0308918810),
    _F32(-0.0170881256),
    _F32(0.0066700901),
    _F32(-0.0012624911),
)
_F0 = _F32(0.0)
_F1 = _F32(1.0)
_FINF = _F32(np.inf)
_F_HALF_PI = _F32(0.5 * math.pi)
_F_THETA_MAX = _F32(THETA_MAX_RAD)
#: theta / (pi/2 - theta) at the clamp: bounds sigma_L, so the lateral row offsets.
Q_MAX = float(_F_THETA_MAX / (_F_HALF_PI - _F_THETA_MAX))
# Vectorisable float maths that keeps NaN / inf semantics (no "nnan", "ninf").
_FAST = {"nsz", "arcp", "contract", "afn", "reassoc"}


@numba.njit(cache=True, inline="always", error_model="numpy", fastmath=_FAST)
def _acos01(c):  # pragma: no cover - numba
    """acos on [0, 1] (float32, A&S 4.4.46) without a libm call."""
    p = _A7
    p = p * c + _A6
    p = p * c + _A5
    p = p * c + _A4
    p = p * c + _A3
    p = p * c + _A2
    p = p * c + _A1
    p = p * c + _A0
    return math.sqrt(max(_F1 - c, _F0)) * p


@numba.njit(cache=True, inline="always", error_model="numpy", fastmath=_FAST)
def _theta_px(z, zl, zr, zu, zd, xl, xc, xr, yu, yc, yd, jump):  # pragma: no cover - numba
    """Incidence angle at one pixel from its 4 neighbours (0 = missing), branch free.

    With P = z (x, y, 1) the horizontal difference P_r - P_l is A r + alpha e_x, with
    r = (x_c, y_c, 1), A = z_r - z_l and alpha = (x_r - x_c) z_r + (x_c - x_l) z_l (a
    missing side is replaced by the centre: one-sided differences); likewise vertically
    B r + beta e_y. Their cross product is n = (-A beta, -alpha B, A beta x_c + alpha B y_c
    + alpha beta) and n . r = alpha beta, exactly.
    """
    lim = jump * z
    okl = (zl > _F0) & (abs(zl - z) <= lim)
    okr = (zr > _F0) & (abs(zr - z) <= lim)
    oku = (zu > _F0) & (abs(zu - z) <= lim)
    okd = (zd > _F0) & (abs(zd - z) <= lim)
    valid = (z > _F0) & (z < _FINF) & (okl | okr) & (oku | okd)
    zl = zl if okl else z
    zr = zr if okr else z
    zu = zu if oku else z
    zd = zd if okd else z
    al = (xc - xl) if okl else _F0
    ar = (xr - xc) if okr else _F0
    bu = (yc - yu) if oku else _F0
    bd = (yd - yc) if okd else _F0
    a = zr - zl
    alpha = ar * zr + al * zl
    b = zd - zu
    beta = bd * zd + bu * zu
    n1 = a * beta
    n2 = alpha * b
    ab = alpha * beta
    n3 = n1 * xc + n2 * yc + ab
    nn = (n1 * n1 + n2 * n2 + n3 * n3) * (xc * xc + yc * yc + _F1)
    c = min(abs(ab) / math.sqrt(nn), _F1)
    t = _acos01(c)
    return t if (valid & (nn > _F0)) else _F0


@numba.njit(cache=True, inline="always", error_model="numpy", fastmath=_FAST)
def _row_theta(depth, zero, v, xn, yn, jump, out):  # pragma: no cover - numba
    """Incidence angles of image row v into out (float32, vectorised)."""
    h, w = depth.shape
    rc = depth[v]
    ru = depth[v - 1] if v > 0 else zero
    rd = depth[v + 1] if v + 1 < h else zero
    yu = yn[v - 1] if v > 0 else _F0
    yd = yn[v + 1] if v + 1 < h else _F0
    yc = yn[v]
    if w == 1:
        out[0] = _theta_px(rc[0], _F0, _F0, ru[0], rd[0], _F0, xn[0], _F0, yu, yc, yd, jump)
        return
    for u in range(1, w - 1):
        out[u] = _theta_px(
            rc[u], rc[u - 1], rc[u + 1], ru[u], rd[u], xn[u - 1], xn[u], xn[u + 1], yu, yc, yd, jump
        )
    out[0] = _theta_px(rc[0], _F0, rc[1], ru[0], rd[0], _F0, xn[0], xn[1], yu, yc, yd, jump)
    e = w - 1
    out[e] = _theta_px(rc[e], rc[e - 1], _F0, ru[e], rd[e], xn[e - 1], xn[e], _F0, yu, yc, yd, jump)


@numba.njit(cache=True, nogil=True, error_model="numpy", fastmath=_FAST)
def params_rows(
    depth, v0, v1, row0, xn, yn, jump, lat, sl, lit, th, theta_only
):  # pragma: no cover - numba
    """Incidence angles and lateral sigmas of rows [v0, v1) (float32, vectorised).

    theta (see :func:`~sim.simulator.kinect_noise.apply.incidence_angle`) comes from
    normals of the clean image; xn, yn are the float32 normalised pixel coordinates
    (u - cx) / fx, (v - cy) / fy. Writes the depth (0 where invalid) to lit, theta to th
    and sigma_L in image px to sl, with lat = (on, a, b, scale) (sigma_L = 0 when off).
    Image row v goes to row v - row0 of sl, lit, th. With theta_only, writes theta to sl
    and nothing else.
    """
    w = depth.shape[1]
    zero = np.zeros(w, dtype=np.float32)
    lon, la, lb, lsc = lat[0], lat[1], lat[2], lat[3]
    for v in range(v0, v1):
        slr = sl[v - row0]
        if theta_only:
            _row_theta(depth, zero, v, xn, yn, jump, slr)
            continue
        thr = th[v - row0]
        _row_theta(depth, zero, v, xn, yn, jump, thr)
        rc = depth[v]
        litr = lit[v - row0]
        for u in range(w):
            z = rc[u]
            litr[u] = z if (z > _F0) & (z < _FINF) else _F0  # lit until shadowed
            tc = min(thr[u], _F_THETA_MAX)
            slr[u] = lon * lsc * (la + lb * tc / (_F_HALF_PI - tc))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def shadow_rows(depth, v0, v1, row0, shift_px, lit):  # pragma: no cover - numba
    """Zero lit (the depth; image row v at v - row0) in rows [v0, v1) where the projector
    cannot see.

    shift_px = fx * projector_offset_m (signed, float32). The projector column of pixel u
    at depth z is u_p = u - shift_px / z (float32). Projector on the right (shift > 0):
    occluders lie to the right, so scan right to left keeping the running min of u_p; a
    pixel whose u_p is larger than that min is behind a nearer surface. Projector on the
    left: mirror image (scan left to right, running max). The shadow band lies on the side
    of a foreground object away from the projector.

    Only the stretch between the first and last "drop" (u_p[u] > u_p[u + 1]; invalid
    pixels count as infinitely far) needs the scan: beyond it u_p is monotone, so those
    pixels are visible (the scan stops once past it at a visible pixel).
    """
    w = depth.shape[1]
    if shift_px == _F0:
        return
    up = np.empty(w, dtype=np.float32)
    far = _FINF if shift_px > _F0 else -_FINF
    for v in range(v0, v1):
        rc = depth[v]
        for u in range(w):  # vectorised
            z = rc[u]
            up[u] = _F32(u) - shift_px / z if (z > _F0) & (z < _FINF) else far
        drops = 0
        for u in range(w - 1):  # vectorised
            drops += up[u] > up[u + 1]
        if drops == 0:
            continue
        first = 0
        while up[first] <= up[first + 1]:
            first += 1
        last = w - 2
        while up[last] <= up[last + 1]:
            last -= 1
        litr = lit[v - row0]
        if shift_px > _F0:
            run = up[last + 1]  # min of the non-decreasing part right of the last drop
            for u in range(last, -1, -1):
                x = up[u]
                if x <= run:
                    run = x
                    if u <= first:
                        break  # non-decreasing to the left: all visible
                else:
                    litr[u] = _F0
        else:
            run = up[first]  # max of the non-decreasing part left of the first drop
            for u in range(first + 1, w):
                x = up[u]
                if x >= run:
                    run = x
                    if u > last:
                        break  # non-decreasing to the right: all visible
                else:
                    litr[u] = _F0
