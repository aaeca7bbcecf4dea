"""Simulated laser scans (KR / KS / KC) against geometry with a known answer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.localization.scans import (
    ScanConfig,
    complete_scan,
    drop_floor,
    level_row,
    raster_scan,
    sampling_scan,
    scan_angles,
    scan_points,
)
from autonomy.perception.camera import CameraIntrinsics, CameraMount
from autonomy.perception.fspf import FSPFConfig, fspf, project_to_floor

INTR = CameraIntrinsics()
MOUNT = CameraMount()


def wall_depth(dist_m: float, angle_rad: float, floor: bool = True) -> np.ndarray:
    """Planar depth of a vertical wall {p : n . p = dist} (robot frame, n at ``angle_rad``
    from the x axis) and the floor z = 0, seen by the default camera on its mount."""
    rot, t = MOUNT.rotation(), MOUNT.translation()
    u, v = np.meshgrid(np.arange(INTR.width), np.arange(INTR.height))
    rays_opt = np.stack([(u - INTR.cx) / INTR.fx, (v - INTR.cy) / INTR.fy, np.ones_like(u, dtype=float)], -1)
    rays = rays_opt @ rot.T  # robot frame; the optical z component is 1, so ray parameter = planar depth
    n = np.array([math.cos(angle_rad), math.sin(angle_rad), 0.0])
    with np.errstate(divide="ignore", invalid="ignore"):
        tw = (dist_m - n @ t) / (rays @ n)
        tf = -t[2] / rays[..., 2]
    tw = np.where(tw > 0, tw, np.inf)
    tf = np.where((tf > 0) & floor, tf, np.inf)
    d = np.minimum(tw, tf)
    d = np.where(np.isfinite(d) & (d < 4.0), d, 0.0)
    return d.astype(np.float32)


def expected_ranges(dist_m: float, angle_rad: float, cfg: ScanConfig) -> np.ndarray:
    """Range from the sensor's floor point to the wall line along each beam centre."""
    a = scan_angles(cfg)
    s = MOUNT.translation()[:2]
    n = np.array([math.cos(angle_rad), math.sin(angle_rad)])
    with np.errstate(divide="ignore"):
        r = (dist_m - n @ s) / (np.cos(a) * n[0] + np.sin(a) * n[1])
    return np.where(r > 0, r, np.inf)


def fit_line(pts: np.ndarray) -> tuple[float, float]:
    """(distance from origin, normal angle) of the least-squares line through 2D points."""
    c = pts.mean(0)
    _, _, vt = np.linalg.svd(pts - c)
    n = vt[-1]
    d = float(n @ c)
    if d < 0:
        n, d = -n, -d
    return d, math.atan2(n[1], n[0])


def test_scan_geometry_is_the_papers() -> None:
    cfg = ScanConfig()
    assert cfg.n_beams == 514  # 180 degrees at 0.35 degrees
    a = scan_angles(cfg)
    assert a[0] == pytest.approx(-math.pi / 2 + math.radians(0.35) / 2, abs=1e-3)
    assert np.allclose(np.diff(a), math.radians(0.35))
    # The level row: 17 degrees up from the centre row.
    assert level_row(INTR, MOUNT) == round(239.5 - 580 * math.tan(math.radians(17)))


@pytest.mark.parametrize("dist,angle", [(2.5, 0.0), (3.0, math.radians(20)), (2.0, math.radians(-35))])
@pytest.mark.parametrize("kind", ["kr", "ks", "kc"])
def test_scans_of_a_wall(kind: str, dist: float, angle: float) -> None:
    cfg = ScanConfig()
    depth = wall_depth(dist, angle)
    if kind == "kr":
        r = raster_scan(depth, INTR, MOUNT, cfg)
    elif kind == "ks":
        r = sampling_scan(depth, INTR, MOUNT, cfg, seed=3)
    else:
        r = complete_scan(depth, INTR, MOUNT, cfg)
    hit = r > 0
    a = scan_angles(cfg)
    # Only the camera's field of view is populated (pitched down, the image's lower
    # corners look a little wider than the horizontal field of view).
    corners = np.array([[-INTR.cx / INTR.fx, (INTR.height - 1 - INTR.cy) / INTR.fy, 1.0]]) @ MOUNT.rotation().T
    half_fov = abs(math.atan2(corners[0, 1], corners[0, 0]))
    assert half_fov > INTR.fov_h_rad / 2
    assert np.all(np.abs(a[hit]) <= half_fov + 0.01)
    n_min = {"kr": 150, "ks": 100, "kc": 150}[kind]
    assert hit.sum() >= n_min
    # Each return is on the wall (no floor returns), within the beam's width.
    exp = expected_ranges(dist, angle, cfg)
    assert np.allclose(r[hit], exp[hit], atol=0.01 + 0.01 * exp[hit])
    # The scan's points, in the robot frame, fit the wall's distance and angle.
    pts = scan_points(r, MOUNT, cfg)
    d_fit, a_fit = fit_line(pts)
    assert d_fit == pytest.approx(dist, abs=0.01)
    assert math.atan2(math.sin(a_fit - angle), math.cos(a_fit - angle)) == pytest.approx(0.0, abs=math.radians(0.5))


def test_uint16_millimetres_give_the_same_scan() -> None:
    depth = wall_depth(2.7, math.radians(10))
    mm = np.round(depth * 1000).astype(np.uint16)
    a = complete_scan(depth, INTR, MOUNT)
    b = complete_scan(mm, INTR, MOUNT)
    assert np.array_equal(a > 0, b > 0)
    assert np.allclose(a, b, atol=0.002)
    assert np.array_equal(sampling_scan(mm, INTR, MOUNT, seed=5), sampling_scan(mm, INTR, MOUNT, seed=5))
    assert not np.array_equal(sampling_scan(mm, INTR, MOUNT, seed=5), sampling_scan(mm, INTR, MOUNT, seed=6))


def test_floor_only_gives_an_empty_scan_and_no_fspf_points() -> None:
    depth = wall_depth(100.0, 0.0)  # the wall is out of range: floor only
    assert (depth > 0).mean() > 0.5
    for r in (raster_scan(depth, INTR, MOUNT), complete_scan(depth, INTR, MOUNT), sampling_scan(depth, INTR, MOUNT, seed=1)):
        assert not (r > 0).any()
    res = fspf(depth, INTR, FSPFConfig(), seed=0, mount=MOUNT)
    assert len(res.points) > 0
    p, n = drop_floor(res.points, res.normals)
    assert len(p) == 0
    p2, _ = project_to_floor(p, n, math.radians(60))
    assert len(p2) == 0


def test_kc_returns_the_nearest_point_per_beam() -> None:
    # A box in front of a wall: where both are seen, the scan holds the box.
    depth = wall_depth(3.5, 0.0)
    box = wall_depth(1.5, 0.0, floor=False)
    u0, u1 = 300, 340
    depth[:, u0:u1] = np.where(box[:, u0:u1] > 0, np.minimum(depth[:, u0:u1], box[:, u0:u1]), depth[:, u0:u1])
    r = complete_scan(depth, INTR, MOUNT)
    a = scan_angles(ScanConfig())
    centre = np.abs(a) < math.radians(1.0)
    assert np.all(np.abs(r[centre] * np.cos(a[centre]) + MOUNT.forward_m - 1.5) < 0.01)


def test_ks_samples_at_most_n_valid_pixels() -> None:
    depth = wall_depth(2.0, 0.0, floor=False)
    few = ScanConfig(ks_samples=10)
    r = sampling_scan(depth, INTR, MOUNT, few, seed=0)
    assert 1 <= (r > 0).sum() <= 10


def test_bad_inputs() -> None:
    with pytest.raises(InputError):
        complete_scan(np.zeros((10, 10), np.float32), INTR, MOUNT)
    with pytest.raises(InputError):
        complete_scan(np.zeros((480, 640), np.int32), INTR, MOUNT)
    with pytest.raises(InputError):
        ScanConfig(resolution_rad=0.0)
    with pytest.raises(InputError):
        ScanConfig(floor_height_m=1.0, max_height_m=0.5)
    with pytest.raises(InputError):
        raster_scan(np.zeros((480, 640), np.float32), INTR, MOUNT, ScanConfig(raster_row=480))
