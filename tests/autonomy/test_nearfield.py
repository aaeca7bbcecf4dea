"""Near-field check (autonomy/perception/nearfield.py) on closed-form depth images of a flat floor
with and without a box standing closer than the camera's minimum range."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
from autonomy.navigation.config import NavigatorConfig
from autonomy.navigation.navigator import Navigator
from autonomy.perception.camera import CameraIntrinsics, CameraMount
from autonomy.perception.nearfield import NearField, NearFieldConfig, line_points

INTR, MOUNT = CameraIntrinsics(), CameraMount()
MIN_RANGE = 0.8


def rays() -> np.ndarray:
    """Robot-frame ray of every pixel per unit of depth (H, W, 3)."""
    u = (np.arange(INTR.width) - INTR.cx) / INTR.fx
    v = (np.arange(INTR.height) - INTR.cy) / INTR.fy
    r = np.stack(np.broadcast_arrays(u[None, :], v[:, None], np.ones((INTR.height, INTR.width))), axis=-1)
    return r @ MOUNT.rotation().T


def scene(box: tuple[float, float, float, float, float] | None = None) -> np.ndarray:
    """Depth of a flat floor (nothing beyond 4 m), with an optional box (x0, x1, y0, y1,
    height) in the robot frame; depths below the minimum range read 0, as the sensor's."""
    d = rays()
    t = MOUNT.translation()
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(d[..., 2] < 0, -t[2] / d[..., 2], np.inf)
        if box is not None:
            x0, x1, y0, y1, h = box
            # Slab intersection of each ray with the box.
            lo = np.full(depth.shape, 0.0)
            hi = np.full(depth.shape, np.inf)
            for k, (a, b) in enumerate(((x0, x1), (y0, y1), (0.0, h))):
                ta, tb = (a - t[k]) / d[..., k], (b - t[k]) / d[..., k]
                lo = np.maximum(lo, np.minimum(ta, tb))
                hi = np.minimum(hi, np.maximum(ta, tb))
            hit = (lo <= hi) & (hi > 0)
            depth = np.where(hit & (lo < depth), lo, depth)
    depth = np.where((depth < MIN_RANGE) | (depth > 4.0), 0.0, depth)
    return depth.astype(np.float32)


def near() -> NearField:
    return NearField(INTR, MOUNT, MIN_RANGE, 0.3)


def test_the_floor_alone_blocks_nothing() -> None:
    nf = near()
    assert nf.active and len(nf.rows) > 5
    assert not nf.blocked_columns(scene()).any()
    assert nf.points(scene()).shape == (0, 2)


def test_box_within_the_minimum_range_blocks_exactly_its_columns() -> None:
    """Brute force: a sampled column is blocked when at least half of its band pixels
    see the box closer than the minimum range instead of the floor."""
    box = (0.7, 1.0, -0.25, 0.15, 1.0)  # 0.48 m ahead of the camera, right of centre
    depth = scene(box)
    nf = near()
    got = nf.blocked_columns(depth)
    clean = scene()
    sub, floor = depth[np.ix_(nf.rows, nf.cols)], clean[np.ix_(nf.rows, nf.cols)]
    want = ((sub == 0) & (floor > 0)).mean(axis=0) >= 0.5
    assert want.sum() > 20
    assert np.array_equal(got, want)
    # Points lie on the blocked columns' sight lines: ahead, outside the robot, no
    # farther than where the lowest band ray reaches the minimum range.
    p = nf.points(depth)
    r = np.hypot(p[:, 0], p[:, 1])
    assert len(p) and (r >= 0.3 - 1e-9).all() and (p[:, 0] <= 0.22 + MIN_RANGE).all()
    # ... and the box's bearings (from the camera) are where they point.
    bearing = np.degrees(np.arctan2(p[:, 1], p[:, 0] - 0.22))
    lo = math.degrees(math.atan2(-0.25, 0.7 - 0.22))
    hi = math.degrees(math.atan2(0.15, 0.7 - 0.22))
    assert bearing.min() > lo - 3.0 and bearing.max() < hi + 3.0


def test_box_seen_beyond_the_minimum_range_is_not_near() -> None:
    assert not near().blocked_columns(scene((1.15, 1.5, -0.3, 0.3, 1.0))).any()


def test_narrow_gaps_like_projector_shadows_are_ignored() -> None:
    """A strip of missing floor 12 px wide (a shadow is at most ~17 px) is not a body;
    40 px is."""
    for width, blocked in ((12, False), (40, True)):
        depth = scene()
        depth[-60:, 300 : 300 + width] = 0.0
        assert near().blocked_columns(depth).any() == blocked


def test_fraction_threshold() -> None:
    nf = near()
    depth = scene()
    rows = nf.rows
    # 40 % of the band rows missing in a wide strip: not blocked; 60 %: blocked.
    d1 = depth.copy()
    d1[np.ix_(rows[: int(0.4 * len(rows))], np.arange(200, 400))] = 0.0
    assert not nf.blocked_columns(d1).any()
    d2 = depth.copy()
    d2[np.ix_(rows[: int(math.ceil(0.6 * len(rows)))], np.arange(200, 400))] = 0.0
    assert nf.blocked_columns(d2).sum() == 50


def test_outer_columns_are_taken_beside_the_path() -> None:
    """Sight lines that end beyond the robot radius sideways keep only their part beside
    the straight path; central ones start at the robot's edge."""
    nf = near()
    end_y = np.abs(nf.lines[:, 3])
    start_y = np.abs(nf.lines[:, 1])
    outer = end_y > 0.3
    assert outer.any() and (~outer).any()
    assert np.allclose(start_y[outer], 0.3)
    assert np.allclose(np.hypot(nf.lines[~outer, 0], nf.lines[~outer, 1]), 0.3, atol=1e-9)


def test_disabled_and_bad_input() -> None:
    nf = NearField(INTR, MOUNT, MIN_RANGE, 0.3, NearFieldConfig(enabled=False))
    assert not nf.blocked_columns(scene((0.6, 0.9, -0.3, 0.3, 1.0))).any()
    with pytest.raises(InputError, match="near_field.min_invalid_fraction"):
        NearFieldConfig(min_invalid_fraction=0.0)
    with pytest.raises(InputError, match="near_field.col_step"):
        NearFieldConfig(col_step=0)
    with pytest.raises(InputError, match="near_field.enabled"):
        NearFieldConfig(enabled="yes")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="depth image shape"):
        near().blocked_columns(np.zeros((10, 10), dtype=np.float32))
    with pytest.raises(InputError, match="minimum range"):
        NearField(INTR, MOUNT, 0.0, 0.3)
    # A band the camera cannot see the floor in is an error, not a near field silently off.
    with pytest.raises(InputError, match=r"near_field: no image row sees the floor between 0\.90 and 0\.50 m"):
        NearField(INTR, MOUNT, MIN_RANGE, 0.3, NearFieldConfig(band_max_depth_m=0.5))
    NearField(INTR, MOUNT, MIN_RANGE, 0.3, NearFieldConfig(band_max_depth_m=0.5, enabled=False))


def test_the_shadow_rule_scales_with_the_focal_length() -> None:
    """The same 30 px-at-f=580 strip of missing floor is a body at full resolution and at
    half resolution (15 px there), and a 12 px-at-f=580 strip is a shadow at both."""
    half = INTR.scaled(320, 240)
    for intr, k in ((INTR, 1), (half, 2)):
        nf = NearField(intr, MOUNT, MIN_RANGE, 0.3, NearFieldConfig(row_step=2, col_step=2))
        for width, blocked in ((12, False), (32, True)):
            depth = np.full((intr.height, intr.width), 1.2, dtype=np.float32)
            depth[:, 100 : 100 + width // k] = 0.0
            assert nf.blocked_columns(depth).any() == blocked, (intr.width, width)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.tuples(*[st.floats(-3, 3, allow_nan=False)] * 4), min_size=1, max_size=5),
    st.floats(0.01, 0.5),
)
def test_line_points_cover_each_segment(lines: list, step: float) -> None:
    segs = np.array(lines, dtype=np.float64)
    p = line_points(segs, step)
    k = 0
    for x0, y0, x1, y1 in segs:
        n = max(1, math.ceil(math.hypot(x1 - x0, y1 - y0) / step)) + 1
        q = p[k : k + n]
        assert q[0] == pytest.approx([x0, y0]) and q[-1] == pytest.approx([x1, y1])
        assert np.all(np.hypot(*np.diff(q, axis=0).T) <= step + 1e-9)
        k += n
    assert k == len(p)


def _navigator(walls: np.ndarray | None = None) -> Navigator:
    g = NavGraph(nodes=(NavNode(id=0, x=0.0, y=0.0), NavNode(id=1, x=5.0, y=0.0)), edges=(NavEdge(s0_id=0, s1_id=1),))
    nav = Navigator(g, NavigatorConfig(), walls=walls)
    nav.set_goal(1, np.array([0.0, 0.0, 0.0]))
    return nav


def test_navigator_does_not_drive_into_the_near_field() -> None:
    """Nothing sensed, but the floor right ahead is hidden: the robot does not drive on
    (it backs off to look); with the same image and no near field it drives at cruise."""
    depth = scene((0.55, 0.85, -0.2, 0.2, 1.2))
    lines = near().sight_lines(depth)
    pose = np.array([0.0, 0.0, 0.0])
    free = _navigator().command(pose, np.zeros((0, 2)), 0.1)
    assert free.state == "driving" and free.velocity[0] > 0.5
    cmd = _navigator().command(pose, np.zeros((0, 2)), 0.1, lines)
    assert cmd.near_points > 0 and cmd.velocity[0] <= 0.0 and cmd.state in ("recovering", "blocked")


def test_navigator_ignores_near_field_a_mapped_wall_explains() -> None:
    """A wall 0.55 m ahead of the camera hides the near floor; the map has it there."""
    depth = scene((0.77, 0.8, -2.0, 2.0, 2.0))
    lines = near().sight_lines(depth)
    assert len(lines)
    wall = np.array([[0.785, -2.0, 0.785, 2.0]])
    nav = _navigator(wall)
    assert nav.surroundings.near_points(np.array([0.0, 0.0, 0.0]), lines).shape == (0, 2)
    # Moved 0.3 m along the wall's normal (the estimate far off), the map no longer explains it.
    assert len(nav.surroundings.near_points(np.array([-0.3, 0.0, 0.0]), lines)) > 0


def test_a_mount_tilted_up_shifts_the_band_to_the_nearest_floor_it_sees() -> None:
    """Tilted 9 degrees up, the camera's lowest row meets the floor 1.24 m away, past the
    configured band (0.9-1.15 m): strict, an error naming it; with ``shift_band`` (a mount
    the stack corrected at run time), the band of the same width from the nearest floor."""
    up = CameraMount(pitch_down_rad=math.radians(8.0))
    with pytest.raises(InputError, match="no image row sees the floor"):
        NearField(INTR, up, MIN_RANGE, 0.3)
    nf = NearField(INTR, up, MIN_RANGE, 0.3, shift_band=True)
    cfg = NearFieldConfig()
    lowest = (INTR.height - 1 - INTR.cy) / INTR.fy  # the bottom row's ray, optical frame
    nearest = up.translation()[2] / math.sin(up.pitch_down_rad + math.atan(lowest)) * math.cos(math.atan(lowest))
    lo, hi = nf.band_m
    assert abs(lo - nearest) < 0.02 and abs((hi - lo) - (cfg.band_max_depth_m - MIN_RANGE - cfg.margin_m)) < 1e-9
    assert nf.active and len(nf.rows) > 0
    # The configured band stays where the camera sees it.
    assert NearField(INTR, MOUNT, MIN_RANGE, 0.3, shift_band=True).band_m == (MIN_RANGE + cfg.margin_m, cfg.band_max_depth_m)
    # A camera looking over the floor entirely (no row meets it): still an error.
    with pytest.raises(InputError, match="no image row sees the floor"):
        NearField(INTR, CameraMount(pitch_down_rad=math.radians(-30.0)), MIN_RANGE, 0.3, shift_band=True)


def test_for_mount_is_the_near_field_rebuilt_with_the_band_shifted() -> None:
    """:meth:`NearField.for_mount` builds the same near field for the corrected mount with
    ``shift_band`` (its settings and robot radius kept); None when no row sees the floor."""
    cfg = NearFieldConfig(col_step=2)
    nf = NearField(INTR, MOUNT, MIN_RANGE, 0.25, cfg)
    up = CameraMount(pitch_down_rad=math.radians(8.0))
    moved, direct = nf.for_mount(up), NearField(INTR, up, MIN_RANGE, 0.25, cfg, shift_band=True)
    assert moved is not None and moved.cfg is cfg and moved.band_m == direct.band_m
    assert np.array_equal(moved.rows, direct.rows) and np.array_equal(moved.lines, direct.lines)
    assert nf.for_mount(CameraMount(pitch_down_rad=math.radians(-30.0))) is None
