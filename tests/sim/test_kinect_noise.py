"""Tests of the Kinect v1 noise model (sim.simulator.kinect_noise) on analytic depth images,
against closed forms and slow numpy references of the kernel's steps."""

from __future__ import annotations

import math
from dataclasses import replace
from statistics import NormalDist

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.perception.camera import CameraIntrinsics
from sim.simulator import kinect_noise as kn
from sim.simulator.kinect_noise import (
    KinectNoiseConfig,
    apply_kinect_noise,
    axial_sigma_m,
    depth_step_m,
    dropout_probability,
    incidence_angle,
    lateral_sigma_px,
)
from sim.simulator.kinect_noise.draws import normals, seed_key

INTR = CameraIntrinsics()
H, W = INTR.height, INTR.width
FB = 580.0 * 0.075  # f b in px m
#: Every term off, no range cut: the identity on valid pixels.
OFF = KinectNoiseConfig(
    axial=False, correlated=False, pattern=False, lateral=False, quantize=False, shadows=False,
    dropouts=False, min_range_m=0.0, max_range_m=math.inf,
)  # fmt: skip
#: The independent model: sigma_z independent from pixel to pixel, no fixed pattern.
INDEPENDENT = KinectNoiseConfig(correlated=False, pattern=False)


def only(**kw) -> KinectNoiseConfig:
    """All terms off and no range cut, except what is given."""
    return replace(OFF, **kw)


def rays(intr: CameraIntrinsics = INTR) -> tuple[np.ndarray, np.ndarray]:
    """Normalised pixel coordinates x = (u - cx) / fx, y = (v - cy) / fy, each H x W."""
    x = (np.arange(intr.width) - intr.cx) / intr.fx
    y = (np.arange(intr.height) - intr.cy) / intr.fy
    return np.meshgrid(x, y)


def wall(z: float) -> np.ndarray:
    """A fronto-parallel wall: constant planar depth."""
    return np.full((H, W), z, dtype=np.float32)


def plane(normal, z0: float) -> tuple[np.ndarray, np.ndarray]:
    """Planar depth of the plane through (0, 0, z0) with this normal, and the true incidence.

    Pixels where the plane is behind the camera (or at infinity) are 0.
    """
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    x, y = rays()
    den = n[0] * x + n[1] * y + n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = n[2] * z0 / den
    ok = np.isfinite(z) & (z > 0) & (z < 50)
    cos_t = np.abs(den) / np.sqrt(x * x + y * y + 1)
    return np.where(ok, z, 0).astype(np.float32), np.arccos(np.clip(cos_t, 0, 1))


def slanted(alpha_rad: float, z0: float) -> tuple[np.ndarray, np.ndarray]:
    """A wall turned by alpha about the vertical axis: incidence alpha at the image centre."""
    return plane((math.sin(alpha_rad), 0.0, -math.cos(alpha_rad)), z0)


def box_scene(z_near: float = 1.0, z_far: float = 3.0) -> np.ndarray:
    """A box (columns 300-399, rows 150-329) in front of a fronto-parallel wall."""
    d = wall(z_far)
    d[150:330, 300:400] = z_near
    return d


# --------------------------------------------------------------------------- references


def shadow_mask_reference(depth: np.ndarray, fx: float, projector_offset_m: float) -> np.ndarray:
    """Slow numpy reference of the projector-shadow test (True = shadowed).

    A valid pixel is shadowed when some valid pixel on the same row, on the projector's
    side, has a smaller projector column u_p = u - fx b / z (b > 0) or a larger one (b < 0).
    Computed in float32 with the kernel's operations, so the masks agree exactly.
    """
    z = np.asarray(depth, dtype=np.float32)
    valid = (z > 0) & np.isfinite(z)
    shift = np.float32(fx * projector_offset_m)
    if shift == 0:
        return np.zeros(z.shape, dtype=bool)
    u = np.arange(z.shape[1], dtype=np.float32)[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        up = u - shift / np.where(valid, z, np.float32(1))
    n = z.shape[0]
    if shift > 0:
        up = np.where(valid, up, np.float32(np.inf))
        suffix = np.minimum.accumulate(up[:, ::-1], axis=1)[:, ::-1]
        strict = np.concatenate([suffix[:, 1:], np.full((n, 1), np.inf, np.float32)], axis=1)
        return valid & (up > strict)
    up = np.where(valid, up, np.float32(-np.inf))
    prefix = np.maximum.accumulate(up, axis=1)
    strict = np.concatenate([np.full((n, 1), -np.inf, np.float32), prefix[:, :-1]], axis=1)
    return valid & (up < strict)


def quantize_depth_reference(z: np.ndarray, cfg: KinectNoiseConfig | None = None) -> np.ndarray:
    """Slow numpy reference of disparity quantisation; 0 (and anything not > 0) gives 0.

    With s = subpixel: k = round(s f b / z) (the disparity d = f b / z in 1/s px units) and
    z_q = s f b / k = f b / (k / s), in float32 like the kernel.
    """
    c = cfg or KinectNoiseConfig()
    z = np.asarray(z, dtype=np.float32)
    fbs = np.float32(float(c.subpixel) * float(c.focal_px) * float(c.baseline_m))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        k = np.rint(fbs / z)
        zq = fbs / k
    return np.where((z > 0) & (k > 0) & np.isfinite(zq), zq, np.float32(0)).astype(np.float32)


# --------------------------------------------------------------------------- closed forms


def test_closed_forms_match_the_paper_and_design_values():
    assert axial_sigma_m(1.0, 0.0) == pytest.approx(0.0012 + 0.0019 * 0.36)
    th = math.radians(70)
    graze = 0.0001 / math.sqrt(2.0) * th**2 / (math.pi / 2 - th) ** 2
    assert axial_sigma_m(2.0, th) == pytest.approx(0.0012 + 0.0019 * 1.6**2 + graze)
    assert lateral_sigma_px(0.0) == pytest.approx(0.8)
    assert lateral_sigma_px(math.radians(45)) == pytest.approx(0.8 + 0.035)
    assert depth_step_m(1.0) == pytest.approx(0.0029, abs=0.0001)
    assert depth_step_m(4.0) == pytest.approx(0.046, abs=0.001)
    p = dropout_probability(np.radians([60.0, 70.0, 77.5, 85.0, 89.0]))
    np.testing.assert_allclose(p, [0, 0, 0.5, 1, 1], atol=1e-12)
    assert np.all(np.isfinite(axial_sigma_m(1.0, np.radians([89.0, 90.0]))))


def test_ziggurat_draws_standard_normals():
    g = np.empty(400_000)
    normals(seed_key(11), g.size, g)
    assert abs(g.mean()) < 0.006
    assert g.std() == pytest.approx(1.0, rel=0.005)
    nd = NormalDist()
    for q in (0.001, 0.01, 0.1, 0.3, 0.5, 0.7, 0.9, 0.99, 0.999):
        assert np.quantile(g, q) == pytest.approx(nd.inv_cdf(q), abs=0.03)
    assert np.mean(np.abs(g) > 3.0) == pytest.approx(2 * nd.cdf(-3.0), rel=0.1)
    assert np.abs(g).max() > 4.1  # the tail beyond the ziggurat's base strip is reached


# --------------------------------------------------------------------------- axial noise, quantisation


def monte_carlo_std(z: float, n: int = 400_000) -> float:
    """Std of the closed-form model (normal sigma_z, then quantisation) by direct sampling."""
    rng = np.random.default_rng(1)
    zn = (z + axial_sigma_m(z, 0.0) * rng.standard_normal(n)).astype(np.float32)
    return float(np.std(quantize_depth_reference(zn) - np.float32(z)))


@pytest.mark.parametrize("z", [1.0, 3.0])
@pytest.mark.parametrize(
    "cfg",
    [INDEPENDENT, KinectNoiseConfig(pattern=False)],
    ids=["independent", "correlated"],
)
def test_flat_wall_spread_and_bias(z, cfg):
    """Per pixel, both models spread a flat wall by Nguyen's sigma_z (plus the disparity
    steps); the correlated one only moves part of that spread into a smooth field. Frames
    are pooled: one frame of a smooth field holds few independent samples."""
    frames = 1 if not cfg.correlated else 12
    out = np.stack([apply_kinect_noise(wall(z), INTR, cfg, seed=5 + k) for k in range(frames)])
    assert np.all(out > 0)  # no shadows, dropouts or range cut on a fronto-parallel wall
    r = out.astype(np.float64) - z
    sigma = float(axial_sigma_m(z, 0.0))  # incidence <= 35 degrees: no grazing term
    step = float(depth_step_m(z))
    # sigma_z / step is 0.66 at 1 m and 0.54 at 3 m: the quantisation error is then close to
    # uniform and independent of the signal (Widrow), so the variances add.
    expected = math.hypot(sigma, step / np.sqrt(12.0))
    assert r.std() == pytest.approx(expected, rel=0.15)
    assert r.std() == pytest.approx(monte_carlo_std(z), rel=0.03 if frames == 1 else 0.05)
    assert abs(r.mean()) < 0.05 * step


def test_the_default_is_the_correlated_model_with_the_fixed_pattern():
    cfg = KinectNoiseConfig()
    assert cfg.correlated and cfg.pattern and cfg.pattern_sigma_px > 0


def test_fixed_pattern_adds_its_disparity_spread_to_a_flat_wall():
    """With the pattern on, a flat wall's spread about the truth is sigma_z, the steps and
    the pattern's z^2 / (f b) sigma_p, in quadrature."""
    z = 1.5
    cfg = KinectNoiseConfig()
    pat = kn.pattern_disparity_px(cfg, INTR)
    assert pat.std() == pytest.approx(cfg.pattern_sigma_px, rel=1e-3)  # made exact per sensor
    assert abs(pat.mean()) < 1e-3 * cfg.pattern_sigma_px
    out = np.stack([apply_kinect_noise(wall(z), INTR, cfg, seed=k) for k in range(8)])
    r = out.astype(np.float64) - z
    sp = z * z / FB * float(pat.std())
    expected = math.hypot(float(axial_sigma_m(z, 0.0)), float(depth_step_m(z)) / math.sqrt(12.0), sp)
    assert r.std() == pytest.approx(expected, rel=0.08)


def test_fixed_pattern_is_the_same_in_every_frame_and_differs_between_sensors():
    """The temporal term: averaged over frames, the per-frame noise goes and the fixed
    pattern stays (z' = f b / (d + p) ~ z - z^2 p / (f b)); another pattern_seed is another
    sensor."""
    z = 2.0
    cfg = KinectNoiseConfig()
    mean = np.mean([apply_kinect_noise(wall(z), INTR, cfg, seed=k) for k in range(40)], axis=0)
    pred = -z * z / FB * kn.pattern_disparity_px(cfg, INTR)
    assert np.corrcoef((mean - z).ravel(), pred.ravel())[0, 1] > 0.95
    other = kn.pattern_disparity_px(replace(cfg, pattern_seed=1), INTR)
    # two independent fields of 96 px correlation hold few independent samples in one
    # image: their chance correlation is typically within +-0.4
    assert abs(np.corrcoef(other.ravel(), pred.ravel())[0, 1]) < 0.7
    # the same seed and sensor give the same image; without the pattern the frames differ
    a = apply_kinect_noise(wall(z), INTR, cfg, seed=3)
    assert a.tobytes() == apply_kinect_noise(wall(z), INTR, cfg, seed=3).tobytes()
    assert a.tobytes() != apply_kinect_noise(wall(z), INTR, replace(cfg, pattern_seed=1), seed=3).tobytes()


def autocorrelation(r: np.ndarray, lags: np.ndarray, axis: int) -> np.ndarray:
    """Mean-removed autocorrelation of each image in r (frames x H x W) along an axis, averaged."""
    r = r - r.mean(axis=(1, 2), keepdims=True)
    var = (r * r).mean()
    n = r.shape[axis + 1]
    return np.array(
        [(np.take(r, range(n - k), axis=axis + 1) * np.take(r, range(k, n), axis=axis + 1)).mean() / var for k in lags]
    )


@pytest.mark.parametrize("length", [16.0, 32.0])
def test_correlation_length_of_a_flat_walls_residual_matches_the_parameter(length):
    """Correlated axial noise alone on a wall at 3 m, where the range term carries
    qz^2 / (a^2 + qz^2) = 99 % of sigma_z^2: the residual's autocorrelation is that share
    times exp(-(r / L)^2), and it falls to share / e at the configured L."""
    z = 3.0
    cfg = only(axial=True, correlated=True, corr_length_px=length)
    r = np.stack([apply_kinect_noise(wall(z), INTR, cfg, seed=k) for k in range(6)]).astype(np.float64) - z
    a, q = cfg.axial_a_m, cfg.axial_b_per_m * (z - cfg.axial_z0_m) ** 2
    share = q * q / (a * a + q * q)
    assert r.std() == pytest.approx(float(axial_sigma_m(z, 0.0)), rel=0.06)
    lags = np.arange(0, int(3 * length))
    for axis in (0, 1):
        acf = autocorrelation(r, lags, axis)
        expected = share * np.exp(-((lags / length) ** 2))
        assert np.abs(acf[1:] - expected[1:]).max() < 0.06
        measured = float(np.interp(-share / math.e, -acf, lags))  # first lag where acf = share / e
        assert measured == pytest.approx(length, rel=0.1)


def test_smooth_field_has_unit_variance_and_the_configured_correlation():
    f = np.stack([kn.smooth_field(s, H, W, 24.0) for s in range(8)]).astype(np.float64)
    assert f.std() == pytest.approx(1.0, abs=0.05)
    lags = np.array([12, 24, 48])
    for axis in (0, 1):
        np.testing.assert_allclose(autocorrelation(f, lags, axis), np.exp(-((lags / 24.0) ** 2)), atol=0.05)
    # every position within a coarse cell has the same variance (no grid pattern)
    per_pos = (f**2).mean(axis=0)[:, :240].reshape(H, 20, 12).mean(axis=(0, 1))
    assert np.ptp(per_pos) < 0.08


def test_correlated_model_keeps_the_per_pixel_randomness_counter_based():
    """Same seed, same image whatever the thread count; the field of a frame is
    smooth_field(seed) itself."""
    cfg = only(axial=True, correlated=True)
    z = 3.0
    for threads in (1, 2, 5):
        a = apply_kinect_noise(wall(z), INTR, replace(cfg, threads=threads), seed=17)
        assert a.tobytes() == apply_kinect_noise(wall(z), INTR, cfg, seed=17).tobytes()
    r = apply_kinect_noise(wall(z), INTR, cfg, seed=17).astype(np.float64) - z
    f = kn.smooth_field(17, H, W, cfg.corr_length_px)
    assert np.corrcoef(r.ravel(), f.ravel())[0, 1] > 0.98


def test_quantised_depths_lie_on_the_disparity_grid():
    cfg = KinectNoiseConfig()
    out = apply_kinect_noise(slanted(math.radians(40), 2.0)[0], INTR, cfg, seed=3)
    k = 8 * FB / out[out > 0].astype(np.float64)
    np.testing.assert_allclose(k, np.rint(k), atol=1e-3)
    assert np.unique(np.rint(k)).size > 50


def test_quantisation_matches_the_numpy_reference_exactly():
    rng = np.random.default_rng(0)
    d = rng.uniform(0.3, 9.0, (H, W)).astype(np.float32)
    d[rng.random((H, W)) < 0.1] = 0
    out = apply_kinect_noise(d, INTR, only(quantize=True), seed=0)
    np.testing.assert_array_equal(out, quantize_depth_reference(d))


def test_range_cut():
    for z in (0.5, 4.5):
        assert not apply_kinect_noise(wall(z), INTR, KinectNoiseConfig(), seed=1).any()
    d = np.linspace(0.1, 6.0, H * W, dtype=np.float32).reshape(H, W)
    out = apply_kinect_noise(d, INTR, replace(OFF, min_range_m=0.8, max_range_m=4.0), seed=1)
    np.testing.assert_array_equal(out, np.where((d >= 0.8) & (d <= 4.0), d, 0))


# --------------------------------------------------------------------------- shadows


def left_right_zeros(out: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Zeros per box row in the 60 columns left and right of the box."""
    rows = out[150:330]
    return (rows[:, 240:300] == 0).sum(axis=1), (rows[:, 400:460] == 0).sum(axis=1)


def test_shadow_band_left_of_a_box_with_the_projector_on_the_right():
    d = box_scene(1.0, 3.0)
    width = FB * (1 / 1.0 - 1 / 3.0)  # 29 px
    out = apply_kinect_noise(d, INTR, only(shadows=True), seed=0)
    left, right = left_right_zeros(out)
    assert np.all(np.abs(left - width) <= 2)
    assert not right.any()
    assert np.all(out[150:330, 300 - int(width) + 1 : 300] == 0)  # contiguous, next to the box
    assert np.all(out[150:330, 300:400] == 1.0)  # the box itself is lit
    assert not (out[:150] == 0).any() and not (out[330:] == 0).any()  # rows without the box
    np.testing.assert_array_equal(out, np.where(shadow_mask_reference(d, INTR.fx, 0.075), 0, d))


def test_flipping_the_projector_flips_the_shadow_side():
    d = box_scene(1.2, 2.5)
    width = FB * (1 / 1.2 - 1 / 2.5)
    out = apply_kinect_noise(d, INTR, only(shadows=True, projector_offset_m=-0.075), seed=0)
    left, right = left_right_zeros(out)
    assert not left.any()
    assert np.all(np.abs(right - width) <= 2)
    np.testing.assert_array_equal(out, np.where(shadow_mask_reference(d, INTR.fx, -0.075), 0, d))


def test_shadow_band_survives_the_full_model():
    out = apply_kinect_noise(box_scene(1.0, 3.0), INTR, KinectNoiseConfig(), seed=4)
    left, right = left_right_zeros(out)
    assert abs(np.median(left) - FB * (1 - 1 / 3.0)) <= 2
    assert right.mean() < 0.5


@pytest.mark.parametrize("offset", [0.075, -0.05])
def test_shadow_scan_matches_reference_on_random_scenes(offset):
    rng = np.random.default_rng(7)
    x, y = rays()
    d = (3.0 + 1.5 * x + 0.5 * np.sin(9 * y)).astype(np.float32)  # a smooth background
    for _ in range(60):
        v, u = rng.integers(0, H - 20), rng.integers(0, W - 40)
        d[v : v + rng.integers(3, 60), u : u + rng.integers(1, 80)] = rng.uniform(0.4, 4.0)
    d[rng.random((H, W)) < 0.02] = 0
    mask = shadow_mask_reference(d, INTR.fx, offset)
    assert 0.01 < mask.mean() < 0.5
    out = apply_kinect_noise(d, INTR, only(shadows=True, projector_offset_m=offset), seed=0)
    np.testing.assert_array_equal(out, np.where(mask, 0, d))


def test_shadow_reference_agrees_with_brute_force_on_a_few_rows():
    rng = np.random.default_rng(3)
    d = rng.uniform(0.5, 4.0, (8, 200)).astype(np.float32)
    d[:, 50:70] = 0.7
    d[rng.random(d.shape) < 0.05] = 0
    for off in (0.075, -0.075):
        mask = shadow_mask_reference(d, 580.0, off)
        valid = d > 0
        up = np.arange(200, dtype=np.float32) - np.float32(580.0 * off) / np.where(valid, d, 1)
        for v in range(8):
            for u in range(200):
                side = slice(u + 1, None) if off > 0 else slice(0, u)
                others = up[v, side][valid[v, side]]
                hidden = (others < up[v, u]).any() if off > 0 else (others > up[v, u]).any()
                assert mask[v, u] == (valid[v, u] and hidden)


# --------------------------------------------------------------------------- incidence, grazing


@pytest.mark.parametrize("alpha_deg", [0.0, 30.0, 45.0, 80.0])
def test_incidence_angle_of_planes(alpha_deg):
    for normal in (
        (math.sin(math.radians(alpha_deg)), 0.0, -math.cos(math.radians(alpha_deg))),
        (0.0, math.sin(math.radians(alpha_deg)), -math.cos(math.radians(alpha_deg))),
    ):
        d, truth = plane(normal, 2.0)
        theta = incidence_angle(d, INTR)
        assert theta.dtype == np.float32 and theta.shape == (H, W)
        inner = np.zeros((H, W), bool)
        inner[2:-2, 2:-2] = True
        valid = d > 0
        for dv in (-2, -1, 0, 1, 2):  # away from holes and the plane's horizon
            for du in (-2, -1, 0, 1, 2):
                inner &= np.roll(valid, (dv, du), axis=(0, 1))
        inner &= truth < math.radians(87)
        assert inner.sum() > 10_000
        err = np.degrees(np.abs(theta[inner] - truth[inner]))
        assert err.max() < 1.0
        assert not theta[~valid].any()


def test_incidence_angle_falls_back_to_one_sided_differences_at_edges():
    d, truth = slanted(math.radians(50), 2.0)
    d[:, 320] = 0  # a hole: its neighbours only have one horizontal neighbour
    d[100:200, 100:300] = 1.0  # a depth jump: no difference across it
    theta = incidence_angle(d, INTR)
    for col in (319, 321, 0, W - 1):
        rows = slice(250, 300)
        np.testing.assert_allclose(theta[rows, col], truth[rows, col], atol=math.radians(1))
    box = incidence_angle(d, INTR)[101:199, 101:299]  # fronto-parallel box
    truth_box = plane((0, 0, -1), 1.0)[1][101:199, 101:299]
    np.testing.assert_allclose(box, truth_box, atol=math.radians(1))


def grazing_region(d: np.ndarray, truth: np.ndarray) -> np.ndarray:
    sel = (np.abs(truth - math.radians(80)) < math.radians(2)) & (d > 1.0) & (d < 3.5)
    sel[:5] = sel[-5:] = False
    sel[:, :5] = sel[:, -5:] = False
    return sel


def test_grazing_wall_drops_out_and_a_fronto_parallel_one_does_not():
    d, truth = slanted(math.radians(80), 2.0)
    sel = grazing_region(d, truth)
    assert sel.sum() > 2000
    out = apply_kinect_noise(d, INTR, only(dropouts=True), seed=2)
    expected = dropout_probability(truth[sel]).mean()  # about 2/3
    assert 0.5 < expected < 0.8
    assert (out[sel] == 0).mean() == pytest.approx(expected, abs=0.04)
    full = apply_kinect_noise(d, INTR, KinectNoiseConfig(), seed=2)
    assert (full[sel] == 0).mean() > 0.5
    assert not (apply_kinect_noise(wall(2.0), INTR, KinectNoiseConfig(), seed=2) == 0).any()


def test_grazing_wall_has_the_larger_axial_spread_of_the_model():
    d, truth = slanted(math.radians(80), 2.0)
    sel = grazing_region(d, truth)
    out = apply_kinect_noise(d, INTR, only(axial=True), seed=8)
    resid = (out[sel].astype(np.float64) - d[sel]) / axial_sigma_m(d[sel], truth[sel])
    assert resid.std() == pytest.approx(1.0, rel=0.05)
    flat = apply_kinect_noise(wall(2.0), INTR, only(axial=True), seed=8)
    grazing_std = (out[sel].astype(np.float64) - d[sel]).std()
    assert grazing_std > 1.5 * (flat.astype(np.float64) - 2.0).std()


def test_uniform_dropout_rate():
    out = apply_kinect_noise(wall(2.0), INTR, only(dropouts=True, dropout_rate=0.1), seed=6)
    assert (out == 0).mean() == pytest.approx(0.1, abs=0.005)


# --------------------------------------------------------------------------- lateral noise


def test_lateral_offsets_are_rounded_normals():
    x, y = np.meshgrid(np.arange(W), np.arange(H))
    col = (1.0 + x / 1000.0).astype(np.float32)  # depth encodes the column ...
    row = (1.0 + y / 1000.0).astype(np.float32)  # ... or the row
    cfg = only(lateral=True, lateral_b_px=0.0)  # sigma_L = 0.8 px everywhere
    inner = (slice(10, H - 10), slice(10, W - 10))
    du = np.rint((apply_kinect_noise(col, INTR, cfg, seed=9) - 1.0) * 1000.0) - x
    dv = np.rint((apply_kinect_noise(row, INTR, cfg, seed=9) - 1.0) * 1000.0) - y
    nd = NormalDist(sigma=0.8)
    for d in (du[inner], dv[inner]):
        assert abs(d.mean()) < 0.01
        assert np.mean(d == 0) == pytest.approx(nd.cdf(0.5) - nd.cdf(-0.5), abs=0.005)
        assert np.mean(np.abs(d) == 2) == pytest.approx(2 * (nd.cdf(2.5) - nd.cdf(1.5)), abs=0.003)
        assert np.abs(d).max() <= 3
    assert abs(np.corrcoef(du[inner].ravel(), dv[inner].ravel())[0, 1]) < 0.01
    # the same draws give the same offsets whatever the depth image
    assert np.array_equal(du, np.rint((apply_kinect_noise(col, INTR, cfg, seed=9) - 1) * 1000) - x)


def test_lateral_noise_blurs_a_depth_edge():
    d = box_scene(1.0, 3.0)
    out = apply_kinect_noise(d, INTR, only(lateral=True), seed=1)
    edge = out[160:320, 398:402]  # both sides of the box's right edge
    assert (edge == 1.0).any() and (edge == 3.0).any()
    assert np.mean(out[160:320, 399] == 3.0) > 0.1  # box pixels that took the wall's depth
    assert np.mean(out[160:320, 400] == 1.0) > 0.1  # wall pixels that took the box's depth
    assert np.all(out[160:320, 320:380] == 1.0)  # far from edges nothing changes


# --------------------------------------------------------------------------- contracts


def test_same_seed_same_output_and_threads_do_not_matter():
    d = box_scene()
    a = apply_kinect_noise(d, INTR, KinectNoiseConfig(), seed=123)
    b = apply_kinect_noise(d, INTR, KinectNoiseConfig(), seed=123)
    c = apply_kinect_noise(d, INTR, KinectNoiseConfig(threads=1), seed=123)
    e = apply_kinect_noise(d, INTR, KinectNoiseConfig(threads=7), seed=123)
    assert a.tobytes() == b.tobytes() == c.tobytes() == e.tobytes()
    f = apply_kinect_noise(d, INTR, KinectNoiseConfig(), seed=124)
    assert np.mean(a != f) > 0.5


def test_out_argument_and_in_place():
    d = box_scene()
    ref = apply_kinect_noise(d, INTR, KinectNoiseConfig(), seed=2)
    buf = np.empty_like(d)
    assert apply_kinect_noise(d, INTR, KinectNoiseConfig(), seed=2, out=buf) is buf
    np.testing.assert_array_equal(buf, ref)
    same = d.copy()
    apply_kinect_noise(same, INTR, KinectNoiseConfig(), seed=2, out=same)
    np.testing.assert_array_equal(same, ref)
    np.testing.assert_array_equal(  # float64 input is converted
        apply_kinect_noise(d.astype(np.float64), INTR, KinectNoiseConfig(), seed=2), ref
    )


def test_invalid_inputs_stay_zero_and_output_is_always_finite():
    rng = np.random.default_rng(5)
    d = rng.uniform(0.5, 5.0, (H, W)).astype(np.float32)
    bad = rng.random((H, W)) < 0.2
    junk = np.array([0.0, -1.0, np.nan, np.inf, -np.inf, 1e-30, 1e30], dtype=np.float32)
    d[bad] = rng.choice(junk, bad.sum())
    tiny_or_huge = np.isin(d, junk[5:])
    for cfg in (KinectNoiseConfig(), OFF, only(quantize=True), only(lateral=True, shadows=True)):
        out = apply_kinect_noise(d, INTR, cfg, seed=1)
        assert np.all(np.isfinite(out)) and np.all(out >= 0)
        assert not out[bad & ~tiny_or_huge].any()
    assert not apply_kinect_noise(np.zeros((H, W), np.float32), INTR, KinectNoiseConfig(), 0).any()


def test_all_terms_off_is_the_identity():
    rng = np.random.default_rng(2)
    d = rng.uniform(0.1, 10.0, (H, W)).astype(np.float32)
    d[rng.random((H, W)) < 0.1] = 0
    np.testing.assert_array_equal(apply_kinect_noise(d, INTR, OFF, seed=3), d)
    cut = apply_kinect_noise(d, INTR, replace(OFF, min_range_m=0.8, max_range_m=4.0), seed=3)
    np.testing.assert_array_equal(cut, np.where((d >= 0.8) & (d <= 4.0), d, 0))


def test_other_image_sizes():
    small = INTR.scaled(160, 120)
    d = np.full((120, 160), 2.0, np.float32)
    out = apply_kinect_noise(d, small, KinectNoiseConfig(), seed=0)
    assert out.shape == (120, 160) and np.all(out > 0)
    one = CameraIntrinsics(width=1, height=1, cx=0.0, cy=0.0)
    assert apply_kinect_noise(np.ones((1, 1)), one, KinectNoiseConfig(), 0).shape == (1, 1)
    assert incidence_angle(np.ones((1, 1)), one)[0, 0] == 0


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("min_range_m", 5.0),
        ("max_range_m", 0.5),
        ("min_range_m", -1.0),
        ("axial_a_m", -0.001),
        ("dropout_full_rad", 1.0),
        ("dropout_rate", 1.5),
        ("subpixel", 0),
        ("subpixel", 8.0),
        ("threads", 0),
        ("focal_px", 0.0),
        ("baseline_m", math.nan),
        ("lateral", 1),
        ("normal_max_rel_jump", 0.0),
        ("correlated", 1),
        ("corr_length_px", 0.0),
        ("pattern_sigma_px", -0.1),
        ("pattern_length_px", math.inf),
        ("pattern_seed", -1),
        ("pattern_seed", 1.0),
    ],
)
def test_bad_config_values_name_the_field(field, value):
    with pytest.raises(InputError) as err:
        KinectNoiseConfig(**{field: value})
    msg = str(err.value)
    assert field in msg or (field == "min_range_m" and "max_range_m" in msg)
    assert "\n" not in msg


def test_bad_arguments_raise_input_error():
    d = wall(2.0)
    cfg = KinectNoiseConfig()
    for call in (
        lambda: apply_kinect_noise(d[:, :-1], INTR, cfg, 0),
        lambda: apply_kinect_noise(d.astype(np.int32), INTR, cfg, 0),
        lambda: apply_kinect_noise(d, "camera", cfg, 0),
        lambda: apply_kinect_noise(d, INTR, {"axial": True}, 0),
        lambda: apply_kinect_noise(d, INTR, cfg, -1),
        lambda: apply_kinect_noise(d, INTR, cfg, 1.5),
        lambda: apply_kinect_noise(d, INTR, cfg, 2**64),
        lambda: apply_kinect_noise(d, INTR, cfg, 0, out=np.empty((H, W))),
        lambda: apply_kinect_noise(d, INTR, cfg, 0, out=np.empty((H, W + 1), np.float32)),
        lambda: incidence_angle(d[1:], INTR),
        lambda: incidence_angle(d, INTR, max_rel_jump=0),
    ):
        with pytest.raises(InputError):
            call()
