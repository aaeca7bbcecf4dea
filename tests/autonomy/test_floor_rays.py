"""Floor rays: the farthest floor point per image column, against a brute-force
reference and on closed-form renders of the shipped building."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.geometry import crosses_any, points_from_frame
from autonomy.maps.raycast import SceneQuery
from autonomy.perception.camera import CameraIntrinsics, DepthCamera, pixel_rays, transform_points
from autonomy.perception.floor_rays import floor_rays
from sim.simulator.blueprints import load_blueprint
from sim.simulator.map_depth import MapDepth

CAM = DepthCamera()
RC = CAM.mount.robot_from_camera()


def reference(depth: np.ndarray, intr: CameraIntrinsics, su: int, sv: int, tol_m: float, tol_q: float) -> np.ndarray:
    """Every pixel's point through the mount; per column on the grid (rows counted from
    the bottom) the deepest whose height is within the tolerance."""
    with np.errstate(invalid="ignore"):
        pts = transform_points(RC, pixel_rays(intr) * depth[..., None].astype(np.float64))
    out = []
    for u in range(0, depth.shape[1], su):
        col = pts[::-1][::sv, u]
        d = depth[::-1][::sv, u].astype(np.float64)
        ok = (d > 0) & np.isfinite(d)
        ok[ok] &= np.abs(col[ok, 2]) <= tol_m + tol_q * d[ok] ** 2
        if ok.any():
            out.append(col[int(np.argmax(np.where(ok, d, -1.0))), :2])
    return np.array(out).reshape(-1, 2)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), su=st.integers(1, 9), sv=st.integers(1, 5))
def test_floor_rays_match_a_brute_force_reference(seed: int, su: int, sv: int) -> None:
    rng = np.random.default_rng(seed)
    intr = CameraIntrinsics().scaled(64, 48)
    # The floor as the camera sees it, with walls and holes in some pixels.
    rays = pixel_rays(intr) @ CAM.mount.rotation().T
    with np.errstate(divide="ignore"):
        floor = np.where(rays[..., 2] < 0, -CAM.mount.height_m / rays[..., 2] * (pixel_rays(intr)[..., 2]), 0.0)
    depth = np.where(rng.random(floor.shape) < 0.5, floor, rng.uniform(0.5, 5.0, floor.shape)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.2] = 0.0
    depth[0, 0] = np.nan
    got = floor_rays(depth, intr, RC, su, sv, 0.05, 0.01)
    np.testing.assert_allclose(got, reference(depth, intr, su, sv, 0.05, 0.01), atol=1e-6)


def test_the_floor_seen_in_an_open_hall_reaches_the_range_and_crosses_no_wall() -> None:
    """Rendered from the map at the atrium's south edge, facing into it: the floor points
    lie out to the camera's range, and no sight line to them crosses a mapped wall; at a
    place 4 m off, some do."""
    vm = load_blueprint("corridor_loop").vectormap
    scene = SceneQuery(vm)
    render = MapDepth(CAM)
    pose = np.array([27.94, 8.82, 0.57])
    pts = floor_rays(render.render(scene, pose), CAM.intrinsics, RC)
    assert len(pts) == math.ceil(CAM.intrinsics.width / 16)
    r = np.hypot(pts[:, 0], pts[:, 1])
    assert r.max() > 0.9 * CAM.max_range_m and r.min() > CAM.min_range_m
    cam_xy = RC[:2, 3]

    def crossing(at: np.ndarray) -> int:
        o = points_from_frame(at, cam_xy[None, :])[0]
        return sum(crosses_any(o, q, vm.segments) for q in points_from_frame(at, pts))

    assert crossing(pose) == 0
    assert crossing(np.array([23.85, 4.26, 0.57])) > 5
