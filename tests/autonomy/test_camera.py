"""Camera model: back-projection against closed form, mount transform, rescaling."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.perception.camera import (
    CameraIntrinsics,
    CameraMount,
    DepthCamera,
    backproject,
    frame_checks,
    pixel_rays,
    transform_points,
)


def test_backproject_matches_pinhole_closed_form() -> None:
    intr = CameraIntrinsics()
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.5, 4.0, size=(intr.height, intr.width)).astype(np.float32)
    pts = backproject(depth, intr)
    for u, v in [(0, 0), (639, 479), (320, 100), (17, 401)]:
        z = float(depth[v, u])
        np.testing.assert_allclose(pts[v, u], [(u - 319.5) * z / 580, (v - 239.5) * z / 580, z], rtol=1e-6)
    # Projecting back gives the pixel.
    u = pts[..., 0] / pts[..., 2] * intr.fx + intr.cx
    np.testing.assert_allclose(u[5], np.arange(intr.width), atol=1e-4)


def test_field_of_view_of_the_kinect() -> None:
    intr = CameraIntrinsics()
    assert math.degrees(intr.fov_h_rad) == pytest.approx(57.8, abs=0.1)
    assert math.degrees(intr.fov_v_rad) == pytest.approx(44.9, abs=0.1)


def test_mount_looks_forward_and_down() -> None:
    m = CameraMount()
    t = m.robot_from_camera()
    axis = t[:3, :3] @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(axis, [math.cos(math.radians(17)), 0.0, -math.sin(math.radians(17))], atol=1e-12)
    right = t[:3, :3] @ np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(right, [0.0, -1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(t[:3, 3], [0.22, 0.0, 0.7])
    # The optical axis meets the floor 0.7 / tan(17 deg) ahead of the camera.
    z = 0.7 / math.sin(math.radians(17))
    p = transform_points(t, np.array([[0.0, 0.0, z]]))[0]
    assert p[2] == pytest.approx(0.0, abs=1e-12)
    assert p[0] == pytest.approx(0.22 + 0.7 / math.tan(math.radians(17)))


@given(st.integers(8, 1280), st.integers(8, 960))
def test_scaled_intrinsics_keep_the_field_of_view(w: int, h: int) -> None:
    intr = CameraIntrinsics()
    s = intr.scaled(w, h)
    assert math.atan((s.width / 2) / s.fx) == pytest.approx(math.atan((intr.width / 2) / intr.fx))
    # The image's outer edges (pixel -0.5 and width - 0.5) map to the same rays.
    for a, b in ((intr, s),):
        assert (-0.5 - a.cx) / a.fx == pytest.approx((-0.5 - b.cx) / b.fx)
        assert (a.height - 0.5 - a.cy) / a.fy == pytest.approx((b.height - 0.5 - b.cy) / b.fy)
    assert pixel_rays(s).shape == (h, w, 3)


def test_bad_shapes_and_intrinsics_are_errors() -> None:
    with pytest.raises(InputError, match="does not match"):
        backproject(np.zeros((10, 10), np.float32), CameraIntrinsics())
    with pytest.raises(InputError, match="fx"):
        CameraIntrinsics(fx=0.0)


def test_depth_camera_derives_field_of_view_and_forward_offset() -> None:
    cam = DepthCamera()
    assert cam.fov_h_rad == CameraIntrinsics().fov_h_rad == 2.0 * math.atan(320.0 / 580.0)
    assert cam.forward_m == 0.22 and (cam.min_range_m, cam.max_range_m) == (0.8, 4.0)
    wide = DepthCamera(intrinsics=CameraIntrinsics(fx=320.0, fy=320.0), mount=CameraMount(forward_m=0.1))
    assert wide.fov_h_rad == pytest.approx(math.pi / 2) and wide.forward_m == 0.1


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"min_range_m": 4.0, "max_range_m": 4.0}, "camera.max_range_m"),
        ({"min_range_m": 5.0}, "camera.max_range_m"),
        ({"max_range_m": float("nan")}, "camera.max_range_m"),
        ({"min_range_m": 0.0}, "camera.min_range_m"),
        ({"min_range_m": -0.5}, "camera.min_range_m"),
        ({"intrinsics": "kinect"}, "camera.intrinsics"),
    ],
)
def test_depth_camera_rejects_a_range_that_is_not_increasing(kwargs: dict, field: str) -> None:
    with pytest.raises(InputError, match=field) as err:
        DepthCamera(**kwargs)
    assert "\n" not in str(err.value)


@settings(deadline=None)
@given(
    st.lists(st.sampled_from([0.0, -1.0, 0.5, 3.0, float("nan"), float("inf")]), min_size=1, max_size=50),
    st.integers(1, 6),
    st.booleans(),
    st.booleans(),
)
def test_frame_checks_match_numpy(values: list[float], stride: int, with_key: bool, change: bool) -> None:
    depth = np.array(values, dtype=np.float32).reshape(1, -1)
    key = None
    if with_key:
        key = depth.ravel()[::stride].copy()
        if change:
            key[-1] = np.float32(7.0) if key[-1] != 7.0 else np.float32(8.0)
    valid = bool(np.any(np.isfinite(depth) & (depth > 0)))
    same = key is not None and bool(np.array_equal(depth.ravel()[::stride], key))
    assert frame_checks(depth, stride, key) == (valid, same)
    n = len(depth.ravel()[::stride])
    assert frame_checks(depth, stride, np.zeros(n + 1, np.float32))[1] is False  # a key of another length
