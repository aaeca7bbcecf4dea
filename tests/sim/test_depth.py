"""Depth rendering against closed form, GL vs ray casting, and seeded Kinect frames."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autonomy.camera import CameraIntrinsics, CameraMount
from autonomy.vectormap import VectorMap
from sim.kinect import GLDepth, KinectCamera, KinectConfig, RaycastDepth, make_depth_backend
from sim.world import WorldConfig, build_world
from tests.helpers import GL

LEVEL = CameraMount(pitch_down_rad=0.0)
SMALL = CameraIntrinsics().scaled(160, 120)  # the ray-cast backend is slow at full size


WALL_H = 1.0


def _wall_world(distance: float, intr: CameraIntrinsics, mount: CameraMount = LEVEL):
    """A single 1 m high wall line across x = distance, robot at the origin facing +x."""
    vm = VectorMap.from_segments(np.array([[distance, -20.0, distance, 20.0]]))
    return build_world(vm, world=WorldConfig(wall_height_m=WALL_H), intrinsics=intr, mount=mount, start_pose=(0.0, 0.0, 0.0))


def _expected_level(distance: float, intr: CameraIntrinsics, mount: CameraMount = LEVEL) -> np.ndarray:
    """Closed form planar depth for a level camera: wall face, floor, or nothing."""
    z_wall = distance - 0.01 - mount.forward_m  # wall face is 1 cm in front of the map line
    v = np.arange(intr.height)[:, None] - intr.cy
    tan_down = v / intr.fy  # ray slope below the axis per unit depth
    with np.errstate(divide="ignore"):
        z_floor = np.where(tan_down > 0, mount.height_m / np.where(tan_down > 0, tan_down, 1), np.inf)
    top_hit = mount.height_m - tan_down * z_wall  # height where the ray meets the wall plane
    z = np.where(z_floor < z_wall, z_floor, np.where(top_hit <= WALL_H, z_wall, 0.0))
    return np.broadcast_to(z, (intr.height, intr.width)).astype(np.float64)


def _backends():
    return (["gl"] if GL else []) + ["raycast"]


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize("distance", [1.5, 3.0])
def test_noiseless_depth_matches_closed_form(backend: str, distance: float) -> None:
    intr = CameraIntrinsics() if backend == "gl" else SMALL
    w = _wall_world(distance, intr)
    d = make_depth_backend(w.model, w.camera_id, intr, backend).render(w.data)
    exp = _expected_level(distance, intr)
    # Away from the wall/floor and wall-top edges (one row either side), within 1 mm.
    edge = np.zeros_like(exp, dtype=bool)
    jumps = np.abs(np.diff(exp, axis=0)) > 0.05
    edge[1:] |= jumps
    edge[:-1] |= jumps
    ok = ~edge
    assert np.abs(d[ok] - exp[ok]).max() < 1e-3
    # The sky above the wall top is background: exactly 0.
    assert (d[(exp == 0) & ok] == 0).all()
    assert ((exp == 0) & ok).sum() > intr.width  # the test does see background


@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_gl_and_raycast_agree_on_a_pitched_camera() -> None:
    intr = SMALL
    w = _wall_world(2.5, intr, CameraMount())
    w.data.qpos[w.robot.qpos_adr[2]] = 0.4  # turned: the wall is seen obliquely
    import mujoco

    mujoco.mj_forward(w.model, w.data)
    a = GLDepth(w.model, w.camera_id, intr).render(w.data)
    b = RaycastDepth(w.model, w.camera_id, intr).render(w.data)
    both = (a > 0) & (b > 0)
    assert both.mean() > 0.9
    assert np.median(np.abs(a[both] - b[both])) < 1e-4
    assert ((a > 0) != (b > 0)).mean() < 0.01


@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_robot_body_is_invisible_and_pitch_sees_floor() -> None:
    intr = CameraIntrinsics()
    w = _wall_world(6.0, intr, CameraMount())
    d = GLDepth(w.model, w.camera_id, intr).render(w.data)
    # Bottom row sees the floor at the closed-form depth (the base itself is hidden).
    ang = math.atan((intr.height - 1 - intr.cy) / intr.fy) + CameraMount().pitch_down_rad
    z = 0.7 / math.sin(ang) * math.cos(ang - CameraMount().pitch_down_rad)
    np.testing.assert_allclose(d[-1, :], z, atol=1e-3)


@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_same_seed_same_frame_and_different_seed_differs() -> None:
    w = _wall_world(2.0, CameraIntrinsics(), CameraMount())
    cam = KinectCamera(w.model, w.camera_id, KinectConfig())
    a = cam.capture(w.data, seed=5).copy()
    b = cam.capture(w.data, seed=5).copy()
    c = cam.capture(w.data, seed=6).copy()
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert a.dtype == np.float32 and np.isfinite(a).all()
    assert ((a == 0) | ((a >= 0.8) & (a <= 4.0))).all()


def test_raycast_fallback_is_chosen_without_gl(monkeypatch: pytest.MonkeyPatch) -> None:
    import sim.kinect as kinect

    def broken(*args, **kwargs):
        raise RuntimeError("no display")

    monkeypatch.setattr(kinect, "GLDepth", broken)
    w = _wall_world(2.0, SMALL)
    with pytest.warns(RuntimeWarning, match="ray-cast depth fallback"):
        b = kinect.make_depth_backend(w.model, w.camera_id, SMALL, "auto")
    assert isinstance(b, RaycastDepth)
    with pytest.raises(RuntimeError, match="OpenGL depth rendering unavailable"):
        kinect.make_depth_backend(w.model, w.camera_id, SMALL, "gl")
