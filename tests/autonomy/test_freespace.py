"""Free space on a grid: the distance transform against brute force, the clearance bound
against exact point-to-segment distances, inside/outside and regions on maps with known
areas."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.common.geometry import point_segment_distance
from autonomy.maps.freespace import (
    FreeSpaceConfig,
    _edt,
    build_free_space,
    convex_hull,
    grid_cell_m,
    hull_mask,
    label_components,
    polygon_area,
)
from sim.simulator import blueprints
from tests.helpers import box_segments, segments_map

R = 0.3


def test_edt_matches_brute_force():
    rng = np.random.default_rng(0)
    wall = rng.random((23, 31)) < 0.04
    wall[5, 7] = True
    got = np.sqrt(_edt(wall))
    wy, wx = np.nonzero(wall)
    yy, xx = np.mgrid[0:23, 0:31]
    ref = np.sqrt(((yy[..., None] - wy) ** 2 + (xx[..., None] - wx) ** 2).min(axis=-1))
    np.testing.assert_allclose(got, ref, atol=1e-9)


def test_labels_are_four_connected_components():
    m = np.zeros((6, 6), dtype=bool)
    m[1, 1] = m[2, 2] = True  # diagonal neighbours: two 4-components
    m[4, 1:5] = True
    lab, sizes = label_components(m)
    assert sorted(sizes.tolist()) == [1, 1, 4]
    assert lab[1, 1] != lab[2, 2]
    assert (lab[~m] == -1).all()


def test_grid_clearance_is_within_the_error_bound_of_the_exact_distance():
    bp = blueprints.load_blueprint(blueprints.ASSETS_DIR / "small_floor")
    fs = build_free_space(bp.vectormap)
    rng = np.random.default_rng(1)
    i = rng.integers(0, fs.shape[0], 3000)
    j = rng.integers(0, fs.shape[1], 3000)
    exact = point_segment_distance(fs.centres(i, j), bp.vectormap.segments).min(axis=1)
    err = np.abs(fs.dist[i, j] - exact)
    assert err.max() <= fs.error_m + 1e-6
    assert (fs.clearance()[i, j] <= exact + 1e-6).all()  # a lower bound, always


def test_a_closed_box_is_one_region_of_the_expected_area_and_the_outside_is_not():
    fs = build_free_space(segments_map(box_segments(0, 0, 10, 6)))
    assert fs.n_regions == 1
    expected = (10 - 2 * R) * (6 - 2 * R)
    assert fs.region_area_m2[0] == pytest.approx(expected, rel=0.03)
    assert fs.outside_area_m2 > 0
    assert fs.region_at(np.array([[5.0, 3.0], [-0.8, 3.0], [11.0, 7.0]])).tolist() == [0, -1, -1]


def test_a_leaky_building_keeps_its_inside_and_drops_the_outside():
    # a 1.2 m gap in the bottom wall joins the inside to the outside on the grid
    fs = build_free_space(segments_map(box_segments(0, 0, 20, 12, gap=(9.4, 10.6))))
    assert fs.region_at(np.array([[10.0, 6.0], [3.0, 3.0], [17.0, 9.0]])).tolist() == [0, 0, 0]
    assert fs.region_at(np.array([[10.0, -1.0], [-1.0, 6.0]])).tolist() == [-1, -1]
    assert fs.region_area_m2[0] == pytest.approx((20 - 2 * R) * (12 - 2 * R), rel=0.06)


def test_a_closed_room_inside_is_a_second_region():
    rows = box_segments(0, 0, 20, 10) + box_segments(14, 6, 18, 9)
    fs = build_free_space(segments_map(rows))
    assert fs.n_regions == 2
    assert fs.region_at(np.array([[16.0, 7.5]]))[0] == 1
    assert fs.region_area_m2[1] == pytest.approx((4 - 2 * R) * (3 - 2 * R), rel=0.08)


def test_no_room_for_the_robot_is_a_one_line_error():
    with pytest.raises(InputError, match="only the outside of the building is free") as e:
        build_free_space(segments_map(box_segments(0, 0, 0.5, 0.5)))
    assert "\n" not in str(e.value)


def test_samples_keep_the_clearance_exactly():
    bp = blueprints.load_blueprint(blueprints.ASSETS_DIR / "small_floor")
    fs = build_free_space(bp.vectormap)
    pts = fs.sample(np.random.default_rng(2), 500, 0.6)
    assert point_segment_distance(pts, bp.vectormap.segments).min() >= 0.6
    assert (fs.region_at(pts) == 0).all()
    with pytest.raises(InputError, match="no place"):
        fs.sample(np.random.default_rng(2), 1, 50.0)


def test_free_cells_are_the_cells_with_the_clearance_kept_only_when_asked():
    """The cells against the grid's own mask, as int32 (half the memory of a building's
    million cells); a one-off query (cache=False) leaves nothing behind, and the cells
    sample() draws from are kept for the next draw."""
    bp = blueprints.load_blueprint(blueprints.ASSETS_DIR / "small_floor")
    fs = build_free_space(bp.vectormap)
    rows, cols = fs.free_cells(0.5, region=None, cache=False)
    want = np.nonzero((fs.clearance() >= 0.5) & (fs.region >= 0))
    assert rows.dtype == cols.dtype == np.int32
    np.testing.assert_array_equal(rows, want[0])
    np.testing.assert_array_equal(cols, want[1])
    again = fs.free_cells(0.5, region=None, cache=False)
    assert again[0] is not rows  # computed afresh: nothing was kept
    kept = fs.sample_cells(0.6)
    assert fs.sample_cells(0.6)[0] is kept[0]
    got = fs.sample(np.random.default_rng(3), 200, 0.6)
    i, j = fs.cell_of(got)
    assert set(zip(i.tolist(), j.tolist(), strict=True)) <= set(zip(kept[0].tolist(), kept[1].tolist(), strict=True))


def test_config_errors_name_the_key():
    with pytest.raises(InputError, match="free_space.cell_m"):
        FreeSpaceConfig(cell_m=0.0)
    with pytest.raises(InputError, match="free_space.padding_m"):
        FreeSpaceConfig(padding_m=0.1)


@settings(max_examples=25, deadline=None)
@given(w=st.floats(2.5, 12.0), h=st.floats(2.5, 12.0), x0=st.floats(-50, 50), y0=st.floats(-50, 50))
def test_a_rectangle_room_has_the_area_a_robot_centre_can_reach(w, h, x0, y0):
    fs = build_free_space(segments_map(box_segments(x0, y0, x0 + w, y0 + h)))
    expected = (w - 2 * R) * (h - 2 * R)
    # the grid's conservative threshold trims up to error_m from each side
    lo = (w - 2 * R - 2 * fs.error_m - 2 * fs.cell_m) * (h - 2 * R - 2 * fs.error_m - 2 * fs.cell_m)
    assert fs.n_regions == 1
    assert lo - 1e-9 <= fs.region_area_m2[0] <= expected + 1e-9


# --------------------------------------------------------------------------- open and large maps


def _open_site() -> list:
    """Four L-shaped wall pieces at the corners of a 40 x 30 m lot: they close nothing."""
    return [(0, 0, 8, 0), (0, 0, 0, 6), (40, 0, 32, 0), (40, 0, 40, 6),
            (40, 30, 32, 30), (40, 30, 40, 24), (0, 30, 8, 30), (0, 30, 0, 24)]


def test_an_open_site_is_detected_and_its_free_space_is_the_walls_hull():
    vm = segments_map(_open_site())
    with pytest.raises(InputError, match="--open"):
        build_free_space(vm, FreeSpaceConfig(open_map=False))
    fs = build_free_space(vm)
    assert fs.is_open and fs.n_regions == 1
    assert fs.hull_area_m2 == pytest.approx(40 * 30)
    # independent reference: the rectangle less a robot-radius band along the 56 m of wall
    # (half-discs at the free ends and the corners' quarter discs are second order)
    lo = 40 * 30 - 56 * (R + fs.error_m + fs.cell_m) - 8 * np.pi * R * R
    assert lo <= fs.region_area_m2[0] <= 40 * 30 - 56 * R + 1e-9
    inside = fs.region_at(np.array([[20.0, 15.0], [2.0, 15.0], [20.0, 1.0]]))
    assert inside.tolist() == [0, 0, 0]
    assert fs.region_at(np.array([[-1.0, 15.0], [20.0, 31.0]])).tolist() == [-1, -1]


def test_a_building_is_not_taken_as_open_and_open_can_be_forced_or_refused():
    rows = box_segments(0, 0, 20, 10) + [(10, 0, 10, 4), (10, 6, 10, 10)]
    assert not build_free_space(segments_map(rows)).is_open
    forced = build_free_space(segments_map(rows), FreeSpaceConfig(open_map=True))
    assert forced.is_open and forced.n_regions == 1  # the box is its own hull
    with pytest.raises(InputError, match="free_space.open_map"):
        FreeSpaceConfig(open_map="yes")  # type: ignore[arg-type]


def test_convex_hull_and_its_mask_against_brute_force():
    rng = np.random.default_rng(7)
    pts = rng.normal(0, 5, (200, 2))
    hull = convex_hull(pts)
    # every point is inside or on every edge's left side
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        cross = (b[0] - a[0]) * (pts[:, 1] - a[1]) - (b[1] - a[1]) * (pts[:, 0] - a[0])
        assert (cross >= -1e-9).all()
    assert polygon_area(np.array([[0, 0], [4, 0], [4, 3], [0, 3]], float)) == pytest.approx(12)
    origin, cell, shape = (-20.0, -20.0), 0.5, (80, 80)
    m = hull_mask(hull, origin, cell, shape)
    i, j = np.mgrid[0 : shape[0], 0 : shape[1]]
    c = np.stack([origin[0] + (j + 0.5) * cell, origin[1] + (i + 0.5) * cell], axis=-1).reshape(-1, 2)
    ok = np.ones(len(c), dtype=bool)
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        ok &= (b[0] - a[0]) * (c[:, 1] - a[1]) - (b[1] - a[1]) * (c[:, 0] - a[0]) >= -1e-9
    assert (m.ravel() == ok).mean() > 0.995  # cells on the boundary may go either way
    assert m.sum() * cell * cell == pytest.approx(polygon_area(hull), rel=0.05)


def test_a_large_extent_gets_a_coarser_grid_within_the_cell_bound():
    rows = box_segments(0, 0, 300, 200) + box_segments(100, 50, 110, 60)
    cfg = FreeSpaceConfig(max_cells=4_000_000)
    c, pad, nx, ny = grid_cell_m((0, 0, 300, 200), cfg)
    assert nx * ny <= 4_000_000 and c > cfg.cell_m
    assert c <= R / 2 and c == pytest.approx(round(c, 2))
    fs = build_free_space(segments_map(rows), cfg)
    assert fs.cell_m == c and fs.wall.size <= 4_000_000
    assert fs.config.padding_m >= R + 2 * c
    # what a robot's centre can reach, less the conservative band of the coarser grid
    expected = (300 - 2 * R) * (200 - 2 * R) - (10 + 2 * R) * (10 + 2 * R)
    assert expected * 0.985 <= fs.region_area_m2[0] <= expected
    # the clearance stays a lower bound of the exact distance on the coarse grid
    rng = np.random.default_rng(8)
    i, j = rng.integers(0, fs.shape[0], 2000), rng.integers(0, fs.shape[1], 2000)
    exact = point_segment_distance(fs.centres(i, j), np.array(rows, float)).min(axis=1)
    assert (fs.clearance()[i, j] <= exact + 1e-6).all()


def test_too_large_even_for_the_coarsest_grid_is_a_one_line_error_naming_the_map():
    with pytest.raises(InputError, match=r"test: a 3000 x 3000 m map needs .* is it in millimetres") as e:
        build_free_space(segments_map(box_segments(0, 0, 3000, 3000)))
    assert "\n" not in str(e.value)
    with pytest.raises(InputError, match="free_space.max_cells"):
        FreeSpaceConfig(max_cells=10)


@settings(max_examples=15, deadline=None)
@given(w=st.floats(200.0, 600.0), h=st.floats(200.0, 600.0), cap=st.integers(1_000_000, 30_000_000))
def test_the_chosen_grid_never_exceeds_the_cell_bound(w, h, cap):
    cfg = FreeSpaceConfig(max_cells=cap)
    try:
        c, pad, nx, ny = grid_cell_m((0.0, 0.0, w, h), cfg)
    except InputError:
        # only when even half the robot radius is too fine
        p = R + 2 * 0.15
        assert (w + 2 * p) * (h + 2 * p) / 0.15**2 > cap * 0.98
        return
    assert nx * ny <= cap
    assert cfg.cell_m <= c <= R / 2 + 1e-12
    assert nx * c >= w + 2 * pad and ny * c >= h + 2 * pad
