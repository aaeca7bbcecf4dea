"""Depth rendering against closed form, GL vs ray casting, and seeded Kinect frames.

GL renders through the render server process here, as it does by default: the test
process never loads Mesa, so tests that import PyTorch can share its worker.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from autonomy.maps.vectormap import VectorMap
from autonomy.perception.camera import CameraIntrinsics, CameraMount
from sim.simulator.gl_depth import culled_geoms, static_geoms
from sim.simulator.kinect import KinectCamera, KinectConfig, RaycastDepth, make_depth_backend
from sim.simulator.world import WorldConfig, build_world
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
    # The face the camera sees is half the face box's thickness in front of the map line.
    z_wall = distance - WorldConfig().wall_face_thickness_m / 2 - mount.forward_m
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
    a = make_depth_backend(w.model, w.camera_id, intr, "gl").render(w.data)
    b = RaycastDepth(w.model, w.camera_id, intr).render(w.data)
    both = (a > 0) & (b > 0)
    assert both.mean() > 0.9
    assert np.median(np.abs(a[both] - b[both])) < 1e-4
    assert ((a > 0) != (b > 0)).mean() < 0.01


@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_robot_body_is_invisible_and_pitch_sees_floor() -> None:
    intr = CameraIntrinsics()
    w = _wall_world(6.0, intr, CameraMount())
    d = make_depth_backend(w.model, w.camera_id, intr, "gl").render(w.data)
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


@pytest.mark.parametrize("process", [True, False])
def test_raycast_fallback_is_chosen_without_gl(monkeypatch: pytest.MonkeyPatch, process: bool) -> None:
    import sim.simulator.kinect as kinect

    def broken(*args, **kwargs):
        raise RuntimeError("no display")

    monkeypatch.setattr(kinect, "GLDepth", broken)
    monkeypatch.setattr(kinect, "ProcessGLDepth", broken)
    w = _wall_world(2.0, SMALL)
    with pytest.warns(RuntimeWarning, match="ray-cast depth fallback"):
        b = kinect.make_depth_backend(w.model, w.camera_id, SMALL, "auto", process=process)
    assert isinstance(b, RaycastDepth)
    with pytest.raises(RuntimeError, match="OpenGL depth rendering unavailable"):
        kinect.make_depth_backend(w.model, w.camera_id, SMALL, "gl", process=process)


@pytest.mark.parametrize("backend", _backends())
def test_nothing_is_rendered_beyond_the_far_distance(backend: str) -> None:
    """A far distance of 4 m in front of a wall at 6 m (planar depth 5.77 m): the wall is
    gone, the floor nearer than 4 m is the closed form, the floor beyond it is gone
    (the ray cast measures planar depth too: image corners are not cut short)."""
    intr = CameraIntrinsics() if backend == "gl" else SMALL
    w = _wall_world(6.0, intr)
    d = make_depth_backend(w.model, w.camera_id, intr, backend, far_m=4.0).render(w.data)
    exp = _expected_level(6.0, intr)
    near = (exp > 0.5) & (exp < 3.95)
    assert near.sum() > intr.width * 10
    assert np.abs(d[near] - exp[near]).max() < 1e-3
    assert (d[exp > 4.05] == 0).all() and (d <= 4.0 + 1e-3).all()


@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_the_far_plane_leaves_the_noisy_frame_in_range_as_it_was() -> None:
    """The default far plane (noise range + 1 m) against an unclipped render of a floor
    and a wall at 6 m: the clean depth within the range agrees to float precision, and
    the noisy frames agree but at a few silhouette pixels (their incidence angle sees an
    unrendered neighbour)."""
    w = _wall_world(6.0, CameraIntrinsics(), CameraMount())
    cfg = KinectConfig()
    assert cfg.far_m() == pytest.approx(cfg.noise.max_range_m + 1.0)
    near = KinectCamera(w.model, w.camera_id, cfg)
    full = KinectCamera(w.model, w.camera_id, KinectConfig(render_far_m=math.inf))
    a, b = near.render_clean(w.data).copy(), full.render_clean(w.data).copy()
    inr = (b > 0) & (b < cfg.far_m() - 0.01)
    assert inr.mean() > 0.3 and (a[b > cfg.far_m() + 0.01] == 0).all()
    np.testing.assert_allclose(a[inr], b[inr], rtol=1e-5)
    na, nb = near.capture(w.data, seed=3), full.capture(w.data, seed=3)
    assert (na != nb).mean() < 1e-3


def test_far_distance_is_checked() -> None:
    from autonomy.common.errors import InputError

    with pytest.raises(InputError, match="kinect.render_far_m"):
        KinectConfig(render_far_m=-1.0)
    with pytest.raises(InputError, match="kinect.render_far_m"):
        KinectConfig(render_far_m=math.nan)
    with pytest.raises(InputError, match="kinect.render_far_m"):
        KinectConfig(render_far_m=0.5)  # nearer than anything the camera measures
    with pytest.raises(InputError, match="kinect.rate_hz"):  # still checked beside it
        KinectConfig(rate_hz=0.0)
    assert KinectConfig(render_far_m=math.inf).far_m() == math.inf
    assert KinectConfig(render_far_m=7.5).far_m() == 7.5


@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_walls_beyond_the_far_plane_or_behind_the_camera_are_not_drawn() -> None:
    """Three short walls: 2 m ahead (drawn), 9 m ahead and 3 m behind (culled with a 5 m
    far plane); the render is the one of a world with the near wall alone (to float
    rounding: the near plane follows the model's extent)."""
    intr = CameraIntrinsics()

    def world(rows):
        vm = VectorMap.from_segments(np.array(rows, dtype=np.float64))
        return build_world(vm, world=WorldConfig(wall_height_m=WALL_H), intrinsics=intr, mount=LEVEL, start_pose=(0.0, 0.0, 0.0))

    w = world([[2.0, -1.0, 2.0, 1.0], [9.0, -1.0, 9.0, 1.0], [-3.0, -1.0, -3.0, 1.0]])
    static = static_geoms(w.model)
    culled = culled_geoms(static, w.model.geom_rbound[static], w.data, w.camera_id, 5.0)
    x = w.data.geom_xpos[culled, 0]
    assert len(culled) == 2 and np.allclose(np.sort(np.round(x)), [-3.0, 9.0])
    groups = w.model.geom_group.copy()
    a = make_depth_backend(w.model, w.camera_id, intr, "gl", far_m=5.0).render(w.data).copy()
    assert np.array_equal(w.model.geom_group, groups)
    near = world([[2.0, -1.0, 2.0, 1.0]])
    b = make_depth_backend(near.model, near.camera_id, intr, "gl", far_m=5.0).render(near.data)
    assert np.array_equal(a > 0, b > 0) and (a > 1.5).any()
    np.testing.assert_allclose(a, b, rtol=1e-6)
