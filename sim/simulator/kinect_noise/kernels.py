"""Numba kernels of the noise itself: per row, the lateral source, axial noise,
quantisation, range cut and dropouts (:func:`noise_rows`), and the whole model on a block
of rows (:func:`block`)."""

from __future__ import annotations

import math

import numba
import numpy as np

from autonomy.common.rng import mix64
from sim.simulator.kinect_noise.config import THETA_MAX_RAD
from sim.simulator.kinect_noise.draws import (
    GAMMA64,
    LAT_G,
    LAT_MASK,
    LAYER_MASK,
    ZIG_X32,
    normal_slow,
)
from sim.simulator.kinect_noise.fields import field_block
from sim.simulator.kinect_noise.geometry import params_rows, shadow_rows

_F32 = np.float32
_F0 = _F32(0.0)
_F1 = _F32(1.0)
_F2 = _F32(2.0)
_F_HALF = _F32(0.5)
_F_TINY = _F32(1e-30)
_F_TWO_M15 = _F32(2.0**-15)
_F_TWO_M16 = _F32(2.0**-16)
_FINF = _F32(np.inf)
_F_HALF_PI = _F32(0.5 * math.pi)
_F_THETA_MAX = _F32(THETA_MAX_RAD)
# Fields of a pixel's word (draws.py has the layout): shifts and masks.
_S11 = np.uint64(11)
_S22 = np.uint64(22)
_S32 = np.uint64(32)
_ONE = np.uint64(1)
_U1 = np.uint32(1)
_U15 = np.uint32(0x7FFF)
_U16 = np.uint32(16)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _split_sigma(sigma, aa, qz):  # pragma: no cover - numba
    """(per-pixel, correlated) parts of sigma_z, with a + qz its constant and range terms:
    the share qz^2 / (a^2 + qz^2) of sigma_z^2 is correlated, the rest is per pixel."""
    r = sigma / math.sqrt(aa * aa + qz * qz + _F_TINY)
    return r * aa, r * qz


@numba.njit(cache=True, inline="always", error_model="numpy")
def _pixel(z, ts, gzu, gfu, pu, udu, z0, prm, corr, pon):  # pragma: no cover - numba
    """Output depth of one pixel (step 5 of noise_rows) from its source's lit depth z and
    incidence angle ts, its random numbers, field and pattern values and its own clean depth
    z0; corr and pon are constants at each call site, so the unused branches compile away."""
    aon, aa, ab, az0, ag, agst, don, dst, dinv, drate, quantize, fbs, zmin, zmax = prm
    tc = min(ts, _F_THETA_MAX)
    q = tc / (_F_HALF_PI - tc)
    graze = ag * q * q / math.sqrt(z) if tc > agst else _F0
    qz = ab * (z - az0) * (z - az0)
    sigma = aon * (aa + qz + graze)
    if corr:
        sw, sc = _split_sigma(sigma, aa, qz)
        zn = z + sw * gzu + sc * gfu
    else:
        zn = z + sigma * gzu
    if pon:
        dk = fbs / zn + pu
        zq = fbs / np.rint(dk) if quantize else fbs / dk
    else:
        k = np.rint(fbs / zn)
        zq = fbs / k if quantize else zn
    pg = don * min(max((ts - dst) * dinv, _F0), _F1)
    ok = (udu >= pg + drate - pg * drate) & (z0 > _F0) & (z0 < _FINF) & (z > _F0)
    ok = ok & (zq > _F0) & (zq < _FINF) & (zq >= zmin) & (zq <= zmax)
    return zq if ok else _F0


@numba.njit(cache=True, nogil=True, error_model="numpy")
def noise_rows(
    depth, v0, v1, row0, lit, th, sl, key, axl, drop, quantize, fbs, zmin, zmax, fld, pat, out
):  # pragma: no cover - numba
    """Lateral source, axial noise, quantisation, range cut and dropouts of rows [v0, v1).

    lit is the lit depth and th the incidence angle of every pixel, sl its sigma_L (image
    row v at v - row0; they must cover every row a lateral offset can reach).
    axl = (on, a, b, z0, c, theta_g): sigma_z = a + b (z - z0)^2 [+ c / sqrt(z) q^2 if
    theta > theta_g], q = theta / (pi/2 - theta), at the source pixel; drop = (on, start,
    1 / (full - start), rate). fbs = subpixel f b, zmin, zmax are float32 (zmax may be inf).
    fld = (on, hrows, j0, rj, rw0, rw1) is the per-frame correlated field (hrows holds coarse
    rows j0.. interpolated to the columns; see fields.field_block) and
    pat = (on, image) the fixed pattern in 1/subpixel px of disparity, added before rounding.

    Per row, lean scalar loops (table lookups, gathers) and loops that LLVM vectorises
    (8 float32 lanes): 1 random word and table lookups (scalar); 2 lateral source index,
    ziggurat fast path, dropout uniform (vectorised); 3 the source's lit depth and theta
    (scalar gathers); 4 ziggurat slow paths (0.4 %); 5 sigma_z, noise, quantisation, range
    cut, dropouts (vectorised). Output pixels whose own input is invalid are 0.
    """
    h, w = depth.shape
    litf = lit.ravel()
    thf = th.ravel()
    prm = (axl[0], axl[1], axl[2], axl[3], axl[4], axl[5], drop[0], drop[1], drop[2], drop[3],
           quantize, fbs, zmin, zmax)  # fmt: skip
    corr, hrows, j0, rj, rw0, rw1 = fld
    pon, patim = pat
    gf = np.zeros(w, dtype=np.float32)  # stands in for the pattern's row when it is off
    hi = np.empty(w, dtype=np.uint32)  # bits 32-63 of the pixel's random word
    g1 = np.empty(w, dtype=np.float32)  # lateral normals
    g2 = np.empty(w, dtype=np.float32)
    x0 = np.empty(w, dtype=np.float32)  # ziggurat X[layer], X[layer + 1]
    x1 = np.empty(w, dtype=np.float32)
    src = np.empty(w, dtype=np.int32)  # flat source index
    gz = np.empty(w, dtype=np.float32)  # axial normal (0 where the slow path is pending)
    ud = np.empty(w, dtype=np.float32)  # dropout uniform
    slow = np.empty(w, dtype=np.bool_)
    zb = np.empty(w, dtype=np.float32)  # source's lit depth
    tb = np.empty(w, dtype=np.float32)  # source's incidence angle
    w32 = np.int32(w)
    r0 = np.int32(row0)
    wmax = np.int32(w - 1)
    hmax = np.int32(h - 1)
    for v in range(v0, v1):
        ctr = key + np.uint64(v * w) * GAMMA64
        for u in range(w):  # 1: scalar (table lookups)
            ctr += GAMMA64
            r = mix64(ctr)
            hi[u] = np.uint32(r >> _S32)
            g1[u] = LAT_G[r & LAT_MASK]
            g2[u] = LAT_G[(r >> _S11) & LAT_MASK]
            i = (r >> _S22) & LAYER_MASK
            x0[u] = ZIG_X32[i]
            x1[u] = ZIG_X32[i + _ONE]
        slr = sl[v - row0]
        nslow = 0
        for u in range(w):  # 2: vectorised
            s = slr[u]
            us = min(max(np.int32(u + np.int32(np.rint(s * g1[u]))), np.int32(0)), wmax)
            vs = min(max(np.int32(v + np.int32(np.rint(s * g2[u]))), np.int32(0)), hmax)
            src[u] = np.int32((vs - r0) * w32 + us)
            b = hi[u]
            x = _F32(np.int32((b >> _U1) & _U15)) * _F_TWO_M15 * x0[u]
            fast = x < x1[u]
            sgn = _F1 - _F2 * _F32(np.int32(b & _U1))
            gz[u] = sgn * x if fast else _F0
            ud[u] = (_F32(np.int32(b >> _U16)) + _F_HALF) * _F_TWO_M16
            slow[u] = not fast
            nslow += not fast
        for u in range(w):  # 3: scalar (gathers)
            j = np.uint64(src[u])
            zb[u] = litf[j]
            tb[u] = thf[j]
        if nslow > 0:  # 4: the ziggurat's slow paths
            ctr = key + np.uint64(v * w) * GAMMA64
            for u in range(w):
                if slow[u]:
                    gz[u] = _F32(normal_slow(mix64(ctr + np.uint64(u + 1) * GAMMA64)))
        rc = depth[v]
        orow = out[v]
        j = rj[v] - j0 if corr else 0
        h0 = hrows[j]  # the correlated field on this row: c0 h0 + c1 h1
        h1 = hrows[j + 1]
        c0 = rw0[v]
        c1 = rw1[v]
        prow = patim[v] if pon else gf
        # 5: vectorised; one loop per combination of the terms, so each is branch free
        if corr and pon:
            for u in range(w):
                g = c0 * h0[u] + c1 * h1[u]
                orow[u] = _pixel(zb[u], tb[u], gz[u], g, prow[u], ud[u], rc[u], prm, True, True)
        elif corr:
            for u in range(w):
                g = c0 * h0[u] + c1 * h1[u]
                orow[u] = _pixel(zb[u], tb[u], gz[u], g, _F0, ud[u], rc[u], prm, True, False)
        elif pon:
            for u in range(w):
                orow[u] = _pixel(zb[u], tb[u], gz[u], _F0, prow[u], ud[u], rc[u], prm, False, True)
        else:
            for u in range(w):
                orow[u] = _pixel(zb[u], tb[u], gz[u], _F0, _F0, ud[u], rc[u], prm, False, False)


@numba.njit(cache=True, nogil=True)
def block(
    depth,
    r0,
    r1,
    margin,
    xn,
    yn,
    jump,
    lat,
    shift_px,
    key,
    axl,
    drop,
    quantize,
    fbs,
    zmin,
    zmax,
    fld,
    pat,
    sl,
    lit,
    th,
    out,
    theta_only,
):  # pragma: no cover - numba
    """The whole model for output rows [r0, r1): parameters and shadows of rows
    [r0 - margin, r1 + margin) into the block's own scratch (sl, lit, th), then the noise.

    margin bounds the lateral row offsets, so blocks are independent (their halo rows are
    computed twice, identically) and can run concurrently. With theta_only, just the
    incidence angles of rows [r0, r1), into sl.
    """
    h = depth.shape[0]
    a0 = max(0, r0 - margin)
    a1 = min(h, r1 + margin)
    if theta_only:
        params_rows(depth, r0, r1, r0, xn, yn, jump, lat, sl, lit, th, True)
        return
    params_rows(depth, a0, a1, a0, xn, yn, jump, lat, sl, lit, th, False)
    shadow_rows(depth, a0, a1, a0, shift_px, lit)
    corr, fkey, kern, nx, iu, wu0, wu1, rj, rw0, rw1 = fld
    j0 = rj[r0] if r1 > r0 else 0
    j1 = rj[r1 - 1] + 1 if (corr and r1 > r0) else j0 + 1
    hrows = field_block(fkey, kern, nx, j0, j1, iu, wu0, wu1) if corr else np.zeros((2, iu.size), np.float32)
    rows = (corr, hrows, j0, rj, rw0, rw1)
    noise_rows(
        depth, r0, r1, a0, lit, th, sl, key, axl, drop, quantize, fbs, zmin, zmax, rows, pat, out
    )
