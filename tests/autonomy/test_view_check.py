"""The view check: back-projection and agreement against brute-force references, and its
verdict on closed-form renders of the shipped building (a view moved as the odometry
says agrees; a robot carried elsewhere, or pushed unseen, does not)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.common.geometry import compose_pose, relative_pose
from autonomy.localization.health import HealthConfig
from autonomy.localization.view_check import (
    ViewCheck,
    ViewCheckConfig,
    move_points,
    sample_points,
    view_agreement,
)
from autonomy.maps.raycast import SceneQuery, load_or_build
from autonomy.perception.camera import CameraIntrinsics, DepthCamera, pixel_rays, transform_points
from autonomy.perception.floor_rays import REACH_STRIDE_PX, floor_reach
from autonomy.stack import LOCALIZATION_GRID
from sim.simulator.blueprints import ASSETS_DIR, load_blueprint
from sim.simulator.map_depth import MapDepth

CAM = DepthCamera()
CFG = ViewCheckConfig()
VIEW_AGREE = HealthConfig().view_agree
"""Below this agreement the health monitor counts a frame as disagreeing."""
RC = CAM.mount.robot_from_camera()
SHAPE = (CAM.intrinsics.height, CAM.intrinsics.width)
#: A corridor spot by an office door (the recovery tests' start), facing along the corridor.
START = np.array([38.31, 33.34, -2.56])
#: In the atrium facing east, no wall within the camera's range: the view holds only floor.
OPEN_HALL = np.array([28.0, 12.0, 0.0])
#: In the west corridor beside the atrium's west door (a kidnapped run's landing).
BY_THE_DOOR = np.array([20.34, 18.69, 0.80])


@pytest.fixture(scope="module")
def scene() -> SceneQuery:
    bp = load_blueprint("corridor_loop")
    return SceneQuery(bp.vectormap, load_or_build(bp.vectormap, ASSETS_DIR / "corridor_loop.vectormap.txt", LOCALIZATION_GRID))


_RENDER = MapDepth(CAM)


def agreement(scene: SceneQuery, then: np.ndarray, now: np.ndarray, odom_inc: np.ndarray) -> float:
    """The check's agreement when the camera saw the map from ``then`` and now from
    ``now``, while the odometry says the robot moved by ``odom_inc``."""
    check = ViewCheck(CFG, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
    assert math.isnan(check.update(0.0, np.zeros(3), _RENDER.render(scene, then)))
    return check.update(1.0 / 30.0, odom_inc, _RENDER.render(scene, now))


# --------------------------------------------------------------------------- kernels


def test_sample_points_back_project_the_grid_and_drop_the_floor() -> None:
    rng = np.random.default_rng(1)
    depth = rng.uniform(0.5, 5.0, (CAM.intrinsics.height, CAM.intrinsics.width)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.2] = 0.0
    depth[5, 8] = np.nan
    pts = sample_points(depth, CAM.intrinsics, RC, CFG.stride_px, CFG.floor_m)
    # Reference: every pixel's ray scaled by its depth, through the mount, then the grid.
    rays = pixel_rays(CAM.intrinsics)
    with np.errstate(invalid="ignore"):
        full = transform_points(RC, rays * depth[..., None].astype(np.float64))
    grid = full[:: CFG.stride_px, :: CFG.stride_px].reshape(-1, 3)
    d = depth[:: CFG.stride_px, :: CFG.stride_px].ravel()
    ok = np.isfinite(d) & (d > 0)
    ref = grid[ok]
    ref = ref[ref[:, 2] > CFG.floor_m]
    assert len(pts) == len(ref) > 100
    np.testing.assert_allclose(pts, ref, atol=1e-9)


def reference_reach(depth, intr, rc, sv: int = 4, tol_m: float = 0.05, tol_q: float = 0.01) -> np.ndarray:
    """Pure-python floor_reach: per REACH_STRIDE_PX-th column, the deepest floor return
    on every sv-th row counted from the bottom."""
    h, w = depth.shape
    with np.errstate(invalid="ignore"):
        pts = transform_points(rc, pixel_rays(intr) * np.asarray(depth, dtype=np.float64)[..., None])
    cols = range(0, w, REACH_STRIDE_PX)
    out = np.zeros(len(cols))
    for k, u in enumerate(cols):
        for v in range(h - 1, -1, -sv):
            z = float(depth[v, u])
            if z > 0 and math.isfinite(z) and abs(pts[v, u, 2]) <= tol_m + tol_q * z * z:
                out[k] = max(out[k], z)
    return out


def reference_agreement(pts, depth, intr, rc, zmin, zmax, tol_m, tol_q, win, empty_margin=None):
    """Pure-python view_agreement."""
    reach = reference_reach(depth, intr, rc)
    inv = np.linalg.inv(rc)
    n_cmp = n_ok = 0
    h, w = depth.shape
    for p in pts:
        x, y, z = inv[:3, :3] @ p + inv[:3, 3]
        if z < zmin or z > zmax:
            continue
        u, v = int(math.floor(intr.fx * x / z + intr.cx + 0.5)), int(math.floor(intr.fy * y / z + intr.cy + 0.5))
        if not (0 <= u < w and 0 <= v < h):
            continue
        near = [float(depth[vv, uu]) for vv in range(v - win, v + win + 1) for uu in range(u - win, u + win + 1)
                if 0 <= vv < h and 0 <= uu < w and depth[vv, uu] > 0 and math.isfinite(depth[vv, uu])]
        if not near:
            # Nothing returned around it: it disagrees when well inside the range and
            # something returned lower down in its column (nothing near blocked the view).
            if empty_margin is not None and zmin + empty_margin <= z <= zmax - empty_margin and reach[u // REACH_STRIDE_PX] >= z:
                n_cmp += 1
            continue
        n_cmp += 1
        n_ok += min(abs(d - z) for d in near) <= tol_m + tol_q * z * z
    return n_cmp, n_ok


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), win=st.integers(0, 3), empty_margin=st.sampled_from([None, 0.0, 0.3]), holes=st.floats(0.3, 0.97))
def test_agreement_matches_a_brute_force_reference(seed: int, win: int, empty_margin: float | None, holes: float) -> None:
    rng = np.random.default_rng(seed)
    intr = CameraIntrinsics().scaled(64, 48)
    depth = rng.uniform(0.3, 5.0, (48, 64)).astype(np.float32)
    depth[rng.random(depth.shape) < holes] = 0.0
    depth[:, rng.integers(0, 64, 5)] = 0.0  # columns that returned nothing
    # Points in front of the camera (some outside its view or range), robot frame.
    pts = np.column_stack([rng.uniform(-1.0, 6.0, 300), rng.uniform(-3.0, 3.0, 300), rng.uniform(-0.5, 2.0, 300)])
    got = view_agreement(pts, depth, intr, RC, 0.8, 4.0, 0.05, 0.01, win, empty_margin)
    ref = reference_agreement(pts, depth.astype(np.float64), intr, RC, 0.8, 4.0, 0.05, 0.01, win, empty_margin)
    assert got == ref


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_floor_reach_matches_a_brute_force_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    intr = CameraIntrinsics().scaled(64, 48)
    rays = pixel_rays(intr) @ CAM.mount.rotation().T
    with np.errstate(divide="ignore"):
        floor = np.where(rays[..., 2] < 0, -CAM.mount.height_m / rays[..., 2], 0.0)
    depth = np.where(rng.random(floor.shape) < 0.6, floor, rng.uniform(0.5, 5.0, floor.shape)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.2] = 0.0
    depth[:, rng.integers(0, 64, 5)] = 0.0
    depth[1, 1] = np.nan
    got = floor_reach(depth, intr, RC)
    np.testing.assert_allclose(got, reference_reach(depth.astype(np.float64), intr, RC), atol=1e-5)
    assert (got > 0).any()


@settings(max_examples=50, deadline=None)
@given(
    inc=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-math.pi, math.pi)),
    p=st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(0, 2)),
)
def test_move_points_agrees_with_composing_poses(inc, p) -> None:
    """A point seen at odometry pose ``then`` is where the world point lies in ``now``'s frame."""
    then = np.array([1.0, -2.0, 0.3])
    now = compose_pose(then, np.array(inc))
    moved = move_points(np.array([p]), then, now)[0]
    world = compose_pose(then, np.array([p[0], p[1], 0.0]))
    expect = relative_pose(now, world)
    np.testing.assert_allclose(moved[:2], expect[:2], atol=1e-9)
    assert moved[2] == p[2]


# --------------------------------------------------------------------------- verdicts


def test_a_view_moved_as_the_odometry_says_agrees(scene) -> None:
    for inc in (np.zeros(3), np.array([0.15, 0.0, 0.0]), np.array([0.1, 0.02, 0.3]), np.array([0.0, 0.0, -0.45])):
        a = agreement(scene, START, compose_pose(START, inc), inc)
        assert a > 0.95, (inc, a)


def test_a_robot_carried_elsewhere_disagrees(scene) -> None:
    # Carried to another corridor, and into an office, while the wheels stood still.
    for there in (np.array([22.91, 30.84, -2.2]), np.array([40.27, 29.91, 1.83]), np.array([25.0, 12.2, 1.57])):
        a = agreement(scene, START, there, np.zeros(3))
        assert a < VIEW_AGREE, (there, a)


def test_a_push_the_odometry_missed_disagrees(scene) -> None:
    """The slip fault's bump: pushed 0.3 m and turned 15 degrees, unseen by the wheels."""
    a = agreement(scene, START, compose_pose(START, np.array([0.3, 0.0, math.radians(15.0)])), np.zeros(3))
    assert a < VIEW_AGREE, a


def test_frames_younger_than_lag_or_older_than_max_lag_are_not_compared(scene) -> None:
    cfg = ViewCheckConfig(lag_s=0.2, max_lag_s=1.0)
    check = ViewCheck(cfg, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
    depth = _RENDER.render(scene, START)
    assert math.isnan(check.update(0.0, np.zeros(3), depth))
    assert math.isnan(check.update(0.1, np.zeros(3), depth))  # too young
    assert check.update(0.2, np.zeros(3), depth) > 0.99
    # After a gap longer than max_lag_s (a blackout) nothing is old enough to compare with.
    assert math.isnan(check.update(1.3, np.zeros(3), depth))
    # By default each frame is compared with the last one.
    check = ViewCheck(CFG, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
    check.update(0.0, np.zeros(3), depth)
    assert check.update(1.0 / 30.0, np.zeros(3), depth) > 0.99
    assert math.isnan(check.update(1.0 / 30.0 + CFG.max_lag_s + 0.01, np.zeros(3), depth))


def test_a_frame_without_evidence_does_not_become_the_reference(scene) -> None:
    """A landing whose first frame shares too few points with the last one (here a frame
    without a valid pixel: a wall closer than the minimum range) is still caught on the
    next frame."""
    check = ViewCheck(CFG, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
    check.update(0.0, np.zeros(3), _RENDER.render(scene, START))
    assert math.isnan(check.update(1 / 30, np.zeros(3), np.zeros(SHAPE, np.float32)))
    assert check.update(2 / 30, np.zeros(3), _RENDER.render(scene, np.array([22.91, 30.84, -2.2]))) < VIEW_AGREE


def person(depth: np.ndarray, u0: int, width: int = 200, z: float = 1.0) -> np.ndarray:
    """``depth`` with a flat person ``z`` metres in front filling columns u0 .. u0 + width."""
    out = depth.copy()
    out[:, u0 : u0 + width] = z
    return out


def test_people_who_walked_on_while_the_view_was_blocked_are_not_compared(scene) -> None:
    """A person a metre in front walks across at 1.4 m/s; others close in front block the
    view (no valid pixel) for 0.3 s, in which the first moved 0.42 m (220 pixels). Against
    the frame before the blockage the view disagrees though the robot stood still: nine
    frames were not stored since that one, and nothing is compared. Between two frames
    the person moves 4.7 cm (25 pixels) and the view agrees."""
    corridor = _RENDER.render(scene, START)
    blocked = np.zeros(SHAPE, np.float32)

    def verdicts(cfg: ViewCheckConfig) -> list[float]:
        check = ViewCheck(cfg, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
        out = [check.update(0.0, np.zeros(3), person(corridor, 120))]
        out += [check.update(k / 30, np.zeros(3), blocked) for k in range(1, 10)]
        out.append(check.update(10 / 30, np.zeros(3), person(corridor, 340)))
        out.append(check.update(11 / 30, np.zeros(3), person(corridor, 365)))
        return out

    got = verdicts(CFG)
    assert all(math.isnan(a) for a in got[:11]), got
    assert got[11] > 0.8
    # Compared across the blockage, the same frames disagree (in a static world: the
    # allowance for people walking on grows with the 0.33 s between the frames).
    assert verdicts(ViewCheckConfig(max_gap_frames=9, movers_mps=0.0))[10] < VIEW_AGREE


def test_a_robot_carried_from_an_open_hall_to_walls_disagrees(scene) -> None:
    """The last view held nothing but floor (no points of its own to compare): this
    frame's points, seen in the last image, land on that floor."""
    check = ViewCheck(CFG, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
    check.update(0.0, np.zeros(3), floor_only())
    assert check.update(1 / 30, np.zeros(3), _RENDER.render(scene, START)) < VIEW_AGREE
    # One way only (the last frame's points in this image) there is no evidence.
    assert len(sample_points(floor_only(), CAM.intrinsics, RC, CFG.stride_px, CFG.floor_m)) == 0


def test_a_robot_carried_from_walls_into_an_open_hall_disagrees(scene) -> None:
    """This view holds nothing but floor; the last view's walls, seen in this image, fall
    on floor farther away or where the camera returned nothing above the floor it saw."""
    assert len(sample_points(_RENDER.render(scene, OPEN_HALL), CAM.intrinsics, RC, CFG.stride_px, CFG.floor_m)) == 0
    for there in (START, BY_THE_DOOR):
        assert agreement(scene, there, OPEN_HALL, np.zeros(3)) < VIEW_AGREE


@pytest.mark.parametrize("hall_frames", [1, 2, 3, 4, 5])
def test_a_landing_after_seconds_of_open_hall_is_caught_on_its_first_frame(scene, hall_frames: int) -> None:
    """The robot drove across an open hall (each frame nothing but floor, so nothing to
    compare) and was put down beside a door: whatever the number of hall frames, the
    landing is judged against the last of them. Frames without evidence are kept as the
    reference: were they dropped, the reference would be forgotten every few frames, and
    a landing that came on such a frame would become the next one's reference unjudged,
    the robot driving on its old belief."""
    check = ViewCheck(CFG, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
    step = np.array([0.01, 0.0, 0.0])
    odom = np.zeros(3)
    for k in range(hall_frames):
        check.update(k / 30, odom, _RENDER.render(scene, compose_pose(OPEN_HALL, odom)))
        odom = compose_pose(odom, step)
    assert check.update(hall_frames / 30, odom, _RENDER.render(scene, BY_THE_DOOR)) < VIEW_AGREE
    # Across the hall itself there is nothing to judge.
    assert math.isnan(check.update(0.0, np.zeros(3), np.zeros(SHAPE, np.float32)))


def test_pixels_blocked_by_something_nearer_than_the_range_are_not_compared(scene) -> None:
    """A person closer than 0.8 m returns nothing, like the open distance, but blocks the
    floor in their columns too: those columns say nothing, in either frame."""
    corridor = _RENDER.render(scene, START)
    blocked = corridor.copy()
    blocked[:, 200:480] = 0.0
    check = ViewCheck(CFG, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
    check.update(0.0, np.zeros(3), corridor)
    assert check.update(1 / 30, np.zeros(3), blocked) > 0.95
    assert check.update(2 / 30, np.zeros(3), corridor) > 0.95


def test_a_person_closing_in_within_a_frame_s_walk_agrees() -> None:
    """A person filling the view walks 6 cm closer between two frames (1.8 m/s, a walk
    and a step aside) while the robot stands: that is what the world did, not the robot,
    and it agrees; in a static world (``movers_mps`` 0) the same frames disagree."""
    person = np.full(SHAPE, 0.92, np.float32)
    person[:, :40] = 0.0
    closer = person - np.float32(0.06)
    for cfg, expect_agree in ((CFG, True), (ViewCheckConfig(movers_mps=0.0), False)):
        check = ViewCheck(cfg, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
        assert math.isnan(check.update(0.0, np.zeros(3), person))
        a = check.update(1 / 30, np.zeros(3), closer)
        assert (a > 0.9) if expect_agree else (a < VIEW_AGREE), (cfg.movers_mps, a)


#: Two consecutive frames of the demo (seed 7, 259.00 and 259.03 s) with their odometry:
#: the robot turning to face a wall about 0.8 m away; depth as float16 (2 mm at 4 m).
DEMO_WALL_TURN = Path(__file__).resolve().parents[1] / "data" / "demo_wall_turn_frames.npz"


def test_a_wall_too_close_whose_foot_the_camera_still_sees_is_not_open_space() -> None:
    """The pitched camera still sees the wall's lower part (deeper than the minimum
    range) but not its upper part, where what the last frame saw beside it falls now.
    Those columns returned no floor beyond the wall's foot, so the points are not
    compared. Counting any return lower in the column as open space, the frame agreed on
    0.27 and the robot was lost for nothing."""
    with np.load(DEMO_WALL_TURN) as z:
        depth, odom, t = z["depth"].astype(np.float32), z["odom"], z["t"]
    check = ViewCheck(CFG, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
    check.update(float(t[0]), odom[0], depth[0])
    a = check.update(float(t[1]), odom[1], depth[1])
    assert math.isnan(a) or a > VIEW_AGREE, a


def floor_only() -> np.ndarray:
    """The floor alone in view (no wall within the camera's range)."""
    rays = pixel_rays(CAM.intrinsics) @ CAM.mount.rotation().T
    with np.errstate(divide="ignore"):
        floor = np.where(rays[..., 2] < 0, -CAM.mount.height_m / rays[..., 2], 0.0)
    return np.where((floor > CAM.min_range_m) & (floor < CAM.max_range_m), floor, 0.0).astype(np.float32)


def test_a_stored_frame_is_the_next_ones_reference(scene) -> None:
    """While relocalizing the stack only stores frames: the first compared frame after it
    is checked against the last stored one, not an older one."""
    check = ViewCheck(CFG, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
    check.update(0.0, np.zeros(3), _RENDER.render(scene, np.array([22.91, 30.84, -2.2])))
    check.store(1 / 30, np.zeros(3), _RENDER.render(scene, START))
    assert math.isnan(check.last)
    assert check.update(2 / 30, np.zeros(3), _RENDER.render(scene, START)) > 0.99


def test_a_view_of_the_floor_alone_carries_no_evidence() -> None:
    """Only the floor in view: it looks alike everywhere, so it is no evidence."""
    check = ViewCheck(CFG, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
    floor = floor_only()
    check.update(0.0, np.zeros(3), floor)
    assert math.isnan(check.update(1.0 / 30.0, np.array([0.5, 0.0, 0.0]), floor))


@pytest.mark.parametrize(
    ("field", "value"),
    [("stride_px", 0), ("window_px", -1), ("min_points", 0), ("max_gap_frames", -1), ("max_lag_s", 0.0), ("tol_m", -0.1), ("lag_s", -1.0), ("floor_m", math.nan), ("empty_margin_m", -0.1)],
)
def test_bad_config_is_a_one_line_error_naming_the_field(field, value) -> None:
    with pytest.raises(InputError, match=rf"view\.{field}: expected"):
        ViewCheckConfig(**{field: value})


def test_lag_beyond_max_lag_is_an_error() -> None:
    with pytest.raises(InputError, match=r"view\.lag_s: expected at most"):
        ViewCheckConfig(lag_s=2.0, max_lag_s=1.0)


def test_a_blocked_frame_stored_while_relocalizing_is_no_reference(scene) -> None:
    """A frame with no valid depth stored while the stack relocalizes leaves nothing to
    compare with: the next frame starts afresh instead of comparing with a blank image."""
    check = ViewCheck(CFG, CAM.intrinsics, RC, CAM.min_range_m, CAM.max_range_m)
    corridor = _RENDER.render(scene, START)
    check.update(0.0, np.zeros(3), corridor)
    check.store(1 / 30, np.zeros(3), np.zeros(SHAPE, np.float32))
    assert math.isnan(check.update(2 / 30, np.zeros(3), corridor))
    assert check.update(3 / 30, np.zeros(3), corridor) > 0.99
