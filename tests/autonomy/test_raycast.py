"""Analytic ray cast (BV2012, Algorithm 2), visibility grid, ray hits: against brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.maps import raycast as rc
from autonomy.maps.raycast import (
    SceneQuery,
    VisibilityGrid,
    VisibilityGridConfig,
    load_or_build,
    ray_hit,
    rays_hit,
    scene_lines,
)
from autonomy.maps.vectormap import VectorMap
from sim.simulator.blueprints import BuildingConfig, generate_building, load_blueprint

N_RAYS = 20_000

# --------------------------------------------------------------------------- brute force


def sweep(seg: np.ndarray, x: float, y: float, n: int = N_RAYS) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions (n, 2) and ray parameters T (n, N) of every ray/segment hit (inf: miss)."""
    ang = np.arange(n) * (2 * np.pi / n) + 1e-4
    d = np.stack([np.cos(ang), np.sin(ang)], 1)
    a = seg[:, 0:2] - (x, y)
    e = seg[:, 2:4] - seg[:, 0:2]
    T = np.empty((n, len(seg)))
    for s in range(0, n, 2000):
        dd = d[s : s + 2000, None, :]
        den = dd[..., 0] * e[None, :, 1] - dd[..., 1] * e[None, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (a[None, :, 0] * e[None, :, 1] - a[None, :, 1] * e[None, :, 0]) / den
            u = (a[None, :, 0] * dd[..., 1] - a[None, :, 1] * dd[..., 0]) / den
        ok = (den != 0) & (t >= 0) & (u >= 0) & (u <= 1)
        T[s : s + 2000] = np.where(ok, t, np.inf)
    return d, T


def point_seg_dist(p: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """(K, M) distances from K points to M segments."""
    a = lines[None, :, 0:2]
    e = lines[None, :, 2:4] - a
    q = p[:, None, :]
    t = np.clip(((q - a) * e).sum(-1) / (e * e).sum(-1), 0.0, 1.0)
    r = a + t[..., None] * e - q
    return np.hypot(r[..., 0], r[..., 1])


def brute_nearest(seg: np.ndarray, x: float, y: float, px: float, py: float) -> float:
    """Nearest hit distance among all segments along the ray from (x, y) through (px, py)."""
    v = np.array([px - x, py - y])
    r = float(np.hypot(*v))
    _, T = sweep_dir(seg, x, y, v / r)
    return float(T.min())


def sweep_dir(seg: np.ndarray, x: float, y: float, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = seg[:, 0:2] - (x, y)
    e = seg[:, 2:4] - seg[:, 0:2]
    den = d[0] * e[:, 1] - d[1] * e[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (a[:, 0] * e[:, 1] - a[:, 1] * e[:, 0]) / den
        u = (a[:, 0] * d[1] - a[:, 1] * d[0]) / den
    ok = (den != 0) & (t >= 0) & (u >= 0) & (u <= 1)
    return d, np.where(ok, t, np.inf)


def angular_intervals(x: float, y: float, lines: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a0 = np.arctan2(lines[:, 1] - y, lines[:, 0] - x)
    a1 = np.arctan2(lines[:, 3] - y, lines[:, 2] - x)
    d = np.angle(np.exp(1j * (a1 - a0)))
    return np.where(d > 0, a0, a1), np.abs(d)


def worst_overlap(x: float, y: float, lines: np.ndarray) -> float:
    """Largest angular overlap (rad) between two returned pieces."""
    lo, w = angular_intervals(x, y, lines)
    worst = 0.0
    for i in range(len(lines)):
        s = np.mod(lo - lo[i], 2 * np.pi)
        o = np.maximum(np.minimum(w[i] - s, w), np.minimum(s + w - 2 * np.pi, w[i]))
        o[i] = 0.0
        worst = max(worst, float(o.max(initial=0.0)))
    return worst


def check_against_brute_force(seg: np.ndarray, x: float, y: float) -> tuple[np.ndarray, np.ndarray]:
    """Checks (a), (b), (c) of the brief for one location; returns the scene lines."""
    lines, src = scene_lines(seg, x, y)
    assert lines.shape == (len(src), 4) and src.dtype == np.int64 and lines.dtype == np.float64
    d, T = sweep(seg, x, y)
    tmin = T.min(1)
    hit = np.isfinite(tmin)
    # (a) every ray's nearest hit lies on a returned piece of the same wall (ties: any of them)
    p = np.array([x, y]) + tmin[hit, None] * d[hit]
    Th = T[hit]
    tied = Th <= tmin[hit, None] + 1e-9
    dist = point_seg_dist(p, lines) if len(lines) else np.full((len(p), 0), np.inf)
    ok = np.zeros(len(p), dtype=bool)
    for j in np.unique(np.flatnonzero(tied.any(0))):
        rows = tied[:, j]
        m = src == j
        if m.any():
            ok[rows] |= dist[rows][:, m].min(1) <= 1e-6
    assert ok.all(), f"({x}, {y}): {np.count_nonzero(~ok)} rays hit a wall piece not returned"
    # (b) sample points along every returned piece are visible: nothing nearer on their ray
    for L, s in zip(lines, src, strict=True):
        assert 0 <= s < len(seg)
        ln = math.hypot(L[2] - L[0], L[3] - L[1])
        assert ln >= rc.MIN_PIECE_M * 0.999
        # the piece lies on its source wall
        assert point_seg_dist(L[None, 0:2], seg[s][None])[0, 0] < 1e-9
        assert point_seg_dist(L[None, 2:4], seg[s][None])[0, 0] < 1e-9
        for f in (0.5, 0.02, 0.25, 0.75, 0.98) if ln > 1e-3 else (0.5,):
            q = L[:2] + f * (L[2:] - L[:2])
            r = math.hypot(q[0] - x, q[1] - y)
            assert brute_nearest(seg, x, y, q[0], q[1]) == pytest.approx(r, abs=1e-7), (
                f"({x}, {y}): occluded point {q} of wall {s} kept"
            )
    # (c) pieces do not overlap angularly
    assert worst_overlap(x, y, lines) < 1e-6
    return lines, src


def free_points(vm: VectorMap, n: int, seed: int, clearance: float = 0.05) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xmin, ymin, xmax, ymax = vm.extent()
    pts = rng.uniform((xmin - 1, ymin - 1), (xmax + 1, ymax + 1), size=(50 * n, 2))
    d = point_seg_dist(pts, vm.segments).min(1)
    return pts[d >= clearance][:n]


# --------------------------------------------------------------------------- Fig. 3 cases


def as_set(lines: np.ndarray, src: np.ndarray) -> list[tuple]:
    return sorted((int(s), *np.round(L, 6).tolist()) for L, s in zip(lines, src, strict=True))


def scene(segs: list[list[float]], x: float = 0.0, y: float = 0.0) -> list[tuple]:
    return as_set(*scene_lines(np.array(segs, dtype=np.float64), x, y))


def test_fig3_case1_not_occluded():
    assert scene([[-1, 5, 1, 5], [3, 2, 4, 2]]) == [(0, -1, 5, 1, 5), (1, 3, 2, 4, 2)]
    # order of the input does not matter
    assert scene([[3, 2, 4, 2], [-1, 5, 1, 5]]) == [(0, 3, 2, 4, 2), (1, -1, 5, 1, 5)]


def test_fig3_case2_fully_occluded():
    assert scene([[-1, 5, 1, 5], [-2, 2, 2, 2]]) == [(1, -2, 2, 2, 2)]
    assert scene([[-2, 2, 2, 2], [1, 5, -1, 5]]) == [(0, -2, 2, 2, 2)]


def test_fig3_case3_partly_occluded():
    # occluder in front of the middle: two pieces (the second one went back on the list)
    assert scene([[-2, 4, 2, 4], [-0.5, 2, 0.5, 2]]) == [
        (0, -2, 4, -1, 4),
        (0, 1, 4, 2, 4),
        (1, -0.5, 2, 0.5, 2),
    ]
    # occluder over one end: one piece
    assert scene([[-2, 4, 2, 4], [0, 2, 2, 2]]) == [(0, -2, 4, 0, 4), (1, 0, 2, 2, 2)]
    # the far line comes first in the input: the scene line is trimmed by the new one
    # (its pieces keep the wall's orientation, here right to left)
    assert scene([[2, 4, -2, 4], [-0.5, 2, 0.5, 2]]) == [
        (0, -1, 4, -2, 4),
        (0, 2, 4, 1, 4),
        (1, -0.5, 2, 0.5, 2),
    ]


def test_fig3_case4_intersecting():
    # an X: each line keeps the part in front of the other (a V opening away from x)
    assert scene([[-1, 1, 1, 3], [-2, 2, 2, 2]]) == [(0, -1, 1, 0, 2), (1, 0, 2, 2, 2)]
    assert scene([[-2, 2, 2, 2], [-1, 1, 1, 3]]) == [(0, 0, 2, 2, 2), (1, -1, 1, 0, 2)]
    # a line piercing a wall: its part behind the wall is hidden, and its part in front
    # hides a stretch of the wall, which is left in two pieces
    assert scene([[0.5, 1, 0.5, 3], [-2, 2, 2, 2]]) == [
        (0, 0.5, 1, 0.5, 2),
        (1, -2, 2, 0.5, 2),
        (1, 1, 2, 2, 2),
    ]


def test_edge_on_and_degenerate():
    # seen edge-on (x on its line): neither visible nor occluding
    assert scene([[2, 0, 4, 0], [5, -1, 5, 1]]) == [(1, 5, -1, 5, 1)]
    # a wall through x is ignored too (x should not be on a wall)
    assert scene([[-1, 0, 1, 0], [-1, 2, 1, 2]]) == [(1, -1, 2, 1, 2)]
    # empty map, empty candidates
    lines, src = scene_lines(np.zeros((0, 4)), 0.0, 0.0)
    assert lines.shape == (0, 4) and src.shape == (0,)
    lines, src = scene_lines(np.array([[1.0, 1, 2, 2]]), 0.0, 0.0, np.zeros(0, np.int64))
    assert lines.shape == (0, 4)


def test_corner_and_collinear_pieces_do_not_hide_each_other():
    # concave room corner seen from inside: both walls complete
    assert scene([[2, -1, 2, 3], [2, 3, -1, 3]]) == [(0, 2, -1, 2, 3), (1, 2, 3, -1, 3)]
    # a wall split in collinear pieces: all of them whole
    assert scene([[-3, 2, -1, 2], [-1, 2, 1, 2], [1, 2, 3, 2]]) == [
        (0, -3, 2, -1, 2),
        (1, -1, 2, 1, 2),
        (2, 1, 2, 3, 2),
    ]
    # overlapping collinear duplicates: the overlap is returned once
    lines, src = scene_lines(np.array([[-2.0, 2, 1, 2], [-1.0, 2, 2, 2]]), 0.0, 0.0)
    assert sorted(np.round(lines[:, [0, 2]].min(1), 9)) == [-2.0, 1.0]
    assert worst_overlap(0.0, 0.0, lines) < 1e-12


def test_max_range_clips_to_disk():
    lines, src = scene_lines(np.array([[-10.0, 3, 10, 3]]), 0.0, 0.0, max_range_m=5.0)
    assert as_set(lines, src) == [(0, -4, 3, 4, 3)]
    lines, _ = scene_lines(np.array([[-10.0, 6, 10, 6]]), 0.0, 0.0, max_range_m=5.0)
    assert len(lines) == 0


def test_orientation_kept():
    lines, src = scene_lines(np.array([[2.0, -1, 2, 1], [3.0, 1, 3, -1]]), 0.0, 0.0)
    assert as_set(lines, src) == [(0, 2, -1, 2, 1)]
    lines, src = scene_lines(np.array([[2.0, 1, 2, 0.5], [3.0, -1, 3, 1]]), 0.0, 0.0)
    assert as_set(lines, src) == [(0, 2, 1, 2, 0.5), (1, 3, -1, 3, 0.75)]


# --------------------------------------------------------------------------- hand-made maps

TRICKY = {
    # room with T-junctions (stems ending on walls), a "+" junction and a stem pointing
    # along a row of test points (seen edge-on from them)
    "junctions": [
        [0, 0, 10, 0], [10, 0, 10, 8], [10, 8, 0, 8], [0, 8, 0, 0],
        [4, 0, 4, 3], [6, 8, 6, 5], [0, 4, 2.5, 4],
        [7, 3, 8, 3], [8, 3, 9, 3], [8, 2, 8, 3], [8, 3, 8, 4],
        [2, 6, 3, 6],
    ],
    # long walls in collinear pieces, touching and overlapping collinear segments
    "collinear": [
        [0, 0, 2, 0], [2, 0, 4, 0], [4, 0, 6, 0], [6, 0, 8, 0], [8, 0, 10, 0],
        [10, 0, 10, 6], [10, 6, 5, 6], [5, 6, 0, 6], [0, 6, 0, 0],
        [3, 3, 5, 3], [4, 3, 6, 3], [6, 3, 7, 3],
    ],
    # crossing segments: an X, a wall pierced by a line, a star
    "crossing": [
        [0, 0, 12, 0], [12, 0, 12, 8], [12, 8, 0, 8], [0, 8, 0, 0],
        [2, 2, 4, 4], [2, 4, 4, 2], [7, 1, 7, 4], [6, 2.5, 9, 2.5],
        [9, 5, 11, 7], [9, 7, 11, 5], [10, 4.5, 10, 7.5],
    ],
    # nested occluders in front of a long wall: splits into 2 (and more) pieces
    "nested": [
        [0, 10, 20, 10], [8, 6, 12, 6], [9.5, 4, 10.5, 4], [9.9, 2.5, 10.1, 2.5],
        [3, 7, 4, 8], [15, 5, 16, 5], [16, 5, 16, 6], [14, 8, 18, 8],
    ],
}
TRICKY_POINTS = {
    "junctions": [(5, 5), (2, 2), (9, 6), (5, 3), (5, 1.5), (3, 4), (1, 6), (9.5, 3.0)],
    "collinear": [(5, 1.5), (1, 3), (9, 3), (5, 4.5), (8, 3), (2, 3)],
    "crossing": [(3, 6), (6, 6), (8, 1), (10, 2), (1, 1), (10, 4)],
    "nested": [(10, 0), (10.05, 1), (9, 0), (12, 1), (5, 2), (15, 2)],
}


@pytest.mark.parametrize("name", sorted(TRICKY))
def test_tricky_maps_against_brute_force(name):
    seg = np.array(TRICKY[name], dtype=np.float64)
    vm = VectorMap(seg, name=name)
    pts = [*TRICKY_POINTS[name], *free_points(vm, 4, seed=len(name))]
    for x, y in pts:
        check_against_brute_force(seg, float(x), float(y))


def test_random_segment_soup_against_brute_force():
    # many crossing, touching and nested segments in every direction
    rng = np.random.default_rng(3)
    seg = rng.uniform(0, 20, (80, 4))
    seg[:30, 2:] = seg[:30, :2] + rng.normal(0, 0.5, (30, 2))
    seg[30:40, 0:2] = seg[40:50, 2:4]  # shared end points
    vm = VectorMap(seg)
    for x, y in free_points(vm, 4, 4, clearance=0.02):
        check_against_brute_force(vm.segments, float(x), float(y))


def test_nested_occluders_split_the_far_wall():
    seg = np.array(TRICKY["nested"][:4], dtype=np.float64)
    lines, src = check_against_brute_force(seg, 10.0, 0.0)
    # far wall visible left and right of the middle occluder, which is split in two itself
    assert np.count_nonzero(src == 0) == 2
    assert np.count_nonzero(src == 1) == 2
    assert np.count_nonzero(src == 2) == 2
    assert np.count_nonzero(src == 3) == 1
    far = np.sort(lines[src == 0][:, [0, 2]], axis=1)
    np.testing.assert_allclose(sorted(far.tolist()), [[0, 10 - 2 * 10 / 6], [10 + 2 * 10 / 6, 20]])


def test_edge_on_stem_does_not_hide_wall():
    # x = (5, 3) sees the stem (8, 3)-(9, 3) of "junctions" edge-on; the wall behind it
    # stays one piece
    seg = np.array(TRICKY["junctions"], dtype=np.float64)
    lines, src = check_against_brute_force(seg, 5.0, 3.0)
    assert 7 not in src.tolist() and 8 not in src.tolist()
    assert np.count_nonzero(src == 1) >= 1


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_generated_maps_against_brute_force(seed):
    vm = generate_building(BuildingConfig(), seed).vectormap
    pts = free_points(vm, 5, seed)
    # and some locations in the corridors / open areas, where more is visible
    bp = generate_building(BuildingConfig(), seed)
    boxes = [*bp.corridors, *bp.open_areas]
    rng = np.random.default_rng(seed)
    for b in boxes[:3]:
        p = rng.uniform(b[:2], b[2:])
        if point_seg_dist(p[None], vm.segments).min() > 0.05:
            pts = np.vstack([pts, p])
    for x, y in pts:
        check_against_brute_force(vm.segments, float(x), float(y))


def test_input_order_does_not_change_the_result():
    # the same walls in reverse order give the same scene (as sets)
    vm = generate_building(BuildingConfig(), 3).vectormap
    seg = vm.segments
    for x, y in free_points(vm, 10, 3):
        a = scene_lines(seg, x, y)
        b = scene_lines(seg[::-1].copy(), x, y)
        n = len(seg)
        sa = as_set(*a)
        sb = as_set(b[0], n - 1 - b[1])
        assert len(sa) == len(sb)
        assert [s[0] for s in sa] == [s[0] for s in sb]
        np.testing.assert_allclose([s[1:] for s in sa], [s[1:] for s in sb], atol=1e-9)


def test_scene_lines_input_errors():
    with pytest.raises(InputError, match=r"shape \(N, 4\)"):
        scene_lines(np.zeros((3, 3)), 0, 0)
    with pytest.raises(InputError, match="finite"):
        scene_lines(np.zeros((1, 4)), math.nan, 0)
    with pytest.raises(InputError, match="candidate"):
        scene_lines(np.ones((2, 4)), 0, 0, np.array([0, 2]))
    with pytest.raises(InputError, match="integer"):
        scene_lines(np.ones((2, 4)), 0, 0, np.array([0.5]))
    with pytest.raises(InputError, match="max_range_m"):
        scene_lines(np.ones((2, 4)), 0, 0, max_range_m=0.0)


# --------------------------------------------------------------------------- ray hits


def test_ray_hit_against_brute_force():
    rng = np.random.default_rng(5)
    lines = rng.uniform(-10, 10, (60, 4))
    dirs = rng.normal(size=(500, 2)) * rng.uniform(0.1, 3.0, (500, 1))
    ox, oy = 0.3, -0.2
    idx, t = rays_hit(lines, ox, oy, dirs)
    assert idx.dtype == np.int64 and t.shape == (500,)
    for k, d in enumerate(dirs):
        _, T = sweep_dir(lines, ox, oy, d)
        j = int(np.argmin(T))
        if np.isfinite(T[j]):
            assert idx[k] == j and t[k] == pytest.approx(T[j], rel=1e-12)
        else:
            assert idx[k] == -1 and t[k] == math.inf
        assert ray_hit(lines, ox, oy, d[0], d[1]) == (int(idx[k]), float(t[k]))
    # t is in units of the direction vector
    i1, t1 = ray_hit(np.array([[2.0, -1, 2, 1]]), 0, 0, 1.0, 0.0)
    i2, t2 = ray_hit(np.array([[2.0, -1, 2, 1]]), 0, 0, 4.0, 0.0)
    assert (i1, t1, i2, t2) == (0, 2.0, 0, 0.5)
    assert ray_hit(np.array([[2.0, -1, 2, 1]]), 0, 0, -1.0, 0.0) == (-1, math.inf)
    assert ray_hit(np.zeros((0, 4)), 0, 0, 1.0, 0.0) == (-1, math.inf)
    with pytest.raises(InputError, match=r"\(K, 2\)"):
        rays_hit(lines, 0, 0, np.zeros(3))


def _indexed_matches_brute_force(lines: np.ndarray, ox: float, oy: float, dirs: np.ndarray, nb: int) -> None:
    offsets, ids = rc.bearing_index(lines, ox, oy, nb)
    assert offsets[0] == 0 and np.all(np.diff(offsets) >= 0) and offsets[-1] == len(ids)
    for b in range(nb):
        assert np.all(np.diff(ids[offsets[b] : offsets[b + 1]]) > 0)  # ascending: ties go to the lower id
    for dx, dy in dirs:
        assert rc.ray_hit_indexed(lines, offsets, ids, ox, oy, dx, dy) == rc.ray_hit_nb(lines, ox, oy, dx, dy)


@pytest.mark.parametrize("nb", [1, 7, 512])
def test_bearing_index_gives_the_brute_force_hit(nb):
    rng = np.random.default_rng(nb)
    ox, oy = 0.3, -0.2
    lines = rng.uniform(-6, 6, (50, 4))
    # Lines through the origin, ending at it, and very short and far ones.
    lines[0] = [ox - 1.0, oy - 2.0, ox + 1.0, oy + 2.0]
    lines[1] = [ox, oy, ox + 3.0, oy - 1.0]
    lines[2] = [ox + 2.0, oy + 2.0, ox + 2.0 + 1e-9, oy + 2.0]
    lines[3] = [ox + 1.0, oy, ox + 5.0, oy]  # on the line through the origin, away from it
    ang = rng.uniform(-math.pi, math.pi, 2000)
    dirs = np.column_stack([np.cos(ang), np.sin(ang)]) * rng.uniform(0.1, 3.0, (2000, 1))
    # Rays straight at every endpoint and along the axes, where pseudo-angles change form.
    ends = np.concatenate([lines[:, :2], lines[:, 2:]]) - (ox, oy)
    axes = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0], [1.0, 1.0], [-1.0, -1.0]])
    _indexed_matches_brute_force(lines, ox, oy, np.concatenate([dirs, ends[np.any(ends != 0, axis=1)], axes]), nb)


def test_bearing_index_on_a_building_matches_brute_force(corridor_loop):
    rng = np.random.default_rng(3)
    ang = np.linspace(-math.pi, math.pi, 1441)
    dirs = np.column_stack([np.cos(ang), np.sin(ang)])
    for x, y in free_points(corridor_loop, 6, 7):
        lines = np.ascontiguousarray(scene_lines(corridor_loop.segments, x, y)[0])
        _indexed_matches_brute_force(lines, x, y, dirs[rng.permutation(len(dirs))[:400]], 512)


def test_ray_hit_on_scene_lines_matches_map():
    vm = generate_building(BuildingConfig(), 1).vectormap
    dirs = np.stack([np.cos(np.linspace(0, 6.28, 720)), np.sin(np.linspace(0, 6.28, 720))], 1)
    for x, y in free_points(vm, 5, 11):
        lines, src = scene_lines(vm.segments, x, y)
        i_s, t_s = rays_hit(lines, x, y, dirs)
        i_m, t_m = rays_hit(vm.segments, x, y, dirs)
        np.testing.assert_allclose(t_s, t_m, atol=1e-9)
        hit = i_s >= 0
        same = src[i_s[hit]] == i_m[hit]
        assert same.mean() > 0.99  # the rest are ties at corners


# --------------------------------------------------------------------------- visibility grid


@pytest.fixture(scope="module")
def corridor_loop() -> VectorMap:
    return load_blueprint("corridor_loop").vectormap


def test_grid_is_conservative(corridor_loop):
    vm = corridor_loop
    cfg = VisibilityGridConfig(cell_m=0.5, max_range_m=6.0)
    grid = VisibilityGrid.build(vm, cfg)
    q = SceneQuery(vm, grid)
    assert q.max_range_m == 6.0
    assert grid.offsets.shape == (grid.nx * grid.ny + 1,) and grid.counts.shape == grid.shape
    pts = free_points(vm, 150, 2, clearance=0.02)
    # include cell borders and corners exactly, and points outside the grid (fallback)
    x0, y0 = grid.origin
    extra = [(x0 + 20 * 0.5, y0 + 10 * 0.5 + 0.25), (x0 + 30 * 0.5, y0 + 15 * 0.5), (-3.0, 5.0), (70.0, 45.0)]
    for x, y in [*map(tuple, pts), *extra]:
        full = scene_lines(vm.segments, x, y, max_range_m=6.0)
        got = q.scene_lines(x, y)
        np.testing.assert_array_equal(full[1], got[1])
        np.testing.assert_allclose(full[0], got[0], atol=1e-12)
        cand = q.candidates(x, y)
        assert cand.dtype == np.int64
        np.testing.assert_array_equal(cand, grid.candidates(x, y))
        got2 = scene_lines(vm.segments, x, y, cand, max_range_m=6.0)
        np.testing.assert_array_equal(full[1], got2[1])
        # every wall within range of the point is a candidate
        near = np.flatnonzero(point_seg_dist(np.array([[x, y]]), vm.segments)[0] <= 6.0)
        assert np.isin(near, cand).all()


def test_grid_clipped_scene_lines_match_sweep_within_range(corridor_loop):
    vm = corridor_loop
    q = SceneQuery(vm)  # default config, grid built here
    R = q.max_range_m
    for x, y in free_points(vm, 4, 9):
        lines, src = q.scene_lines(x, y)
        d, T = sweep(vm.segments, x, y, 4000)
        tmin = T.min(1)
        inr = tmin < R - 1e-6
        p = np.array([x, y]) + tmin[inr, None] * d[inr]
        j = T[inr].argmin(1)
        dist = point_seg_dist(p, lines)
        ok = [dist[k, src == j[k]].min(initial=np.inf) <= 1e-6 for k in range(len(p))]
        assert np.mean(ok) > 0.999
        assert (np.hypot(lines[:, 0::2] - x, lines[:, 1::2] - y) <= R + 1e-9).all()


def test_grid_save_load_roundtrip(tmp_path, corridor_loop):
    g = VisibilityGrid.build(corridor_loop, VisibilityGridConfig(cell_m=1.0, max_range_m=5.0))
    p = g.save(tmp_path / "g.visgrid.npz")
    h = VisibilityGrid.load(p)
    np.testing.assert_array_equal(g.offsets, h.offsets)
    np.testing.assert_array_equal(g.indices, h.indices)
    assert (h.origin, h.shape, h.config, h.n_segments, h.key) == (g.origin, g.shape, g.config, g.n_segments, g.key)
    np.testing.assert_array_equal(g.candidates(10.2, 7.7), h.candidates(10.2, 7.7))
    with pytest.raises(InputError, match="file not found"):
        VisibilityGrid.load(tmp_path / "nope.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip at all")
    with pytest.raises(InputError, match="not a visibility grid file"):
        VisibilityGrid.load(bad)
    # a file whose arrays do not match its key
    with np.load(p) as z:
        arrays = dict(z)
    arrays["segments"] = arrays["segments"] + 1.0
    np.savez(tmp_path / "tampered.npz", **arrays)
    with pytest.raises(InputError, match="does not match"):
        VisibilityGrid.load(tmp_path / "tampered.npz")
    with pytest.raises(InputError, match="another map"):
        SceneQuery(generate_building(BuildingConfig(), 0).vectormap, g)


def test_load_or_build_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    cfg = VisibilityGridConfig(cell_m=1.0, max_range_m=4.0)
    vm = generate_building(BuildingConfig(), 0).vectormap
    map_path = tmp_path / "m.vectormap.txt"
    cache = tmp_path / "m.vectormap.txt.visgrid.npz"
    g1 = load_or_build(vm, map_path, cfg)
    assert cache.is_file()
    stamp = cache.stat().st_mtime_ns
    g2 = load_or_build(vm, map_path, cfg)
    assert cache.stat().st_mtime_ns == stamp  # reused, not rewritten
    np.testing.assert_array_equal(g1.indices, g2.indices)
    # a changed map rebuilds (same cache file)
    seg = vm.segments.copy()
    seg[0, 0] += 0.5
    vm2 = VectorMap(seg)
    g3 = load_or_build(vm2, map_path, cfg)
    assert g3.key != g1.key and VisibilityGrid.load(cache).key == g3.key
    # a changed config rebuilds
    g4 = load_or_build(vm2, map_path, VisibilityGridConfig(cell_m=1.0, max_range_m=5.0))
    assert g4.config.max_range_m == 5.0 and VisibilityGrid.load(cache).config.max_range_m == 5.0
    # a corrupt cache file is rebuilt, not an error
    cache.write_bytes(b"PK\x03\x04garbage")
    g5 = load_or_build(vm2, map_path, cfg)
    assert g5.key == g3.key and VisibilityGrid.load(cache).key == g3.key
    # an unwritable directory falls back to ~/.cache/depthnav
    blocked = tmp_path / "afile"
    blocked.write_text("x")
    g6 = load_or_build(vm, blocked / "m.vectormap.txt", cfg)
    home_cache = list((tmp_path / "home" / ".cache" / "depthnav").glob("*.visgrid.npz"))
    assert len(home_cache) == 1 and VisibilityGrid.load(home_cache[0]).key == g6.key == g1.key
    # and is found there next time
    stamp = home_cache[0].stat().st_mtime_ns
    load_or_build(vm, blocked / "m.vectormap.txt", cfg)
    assert home_cache[0].stat().st_mtime_ns == stamp
    # no map path: the home cache
    assert load_or_build(vm, None, cfg).key == g1.key


def test_grid_config_errors():
    with pytest.raises(InputError, match="cell_m"):
        VisibilityGridConfig(cell_m=0.0)
    with pytest.raises(InputError, match="max_range_m"):
        VisibilityGridConfig(max_range_m=math.inf)
    with pytest.raises(InputError, match="no segments"):
        VisibilityGrid.build(VectorMap(np.zeros((0, 4))))


def test_benchmark_runs(corridor_loop):
    assert rc.benchmark_scene_lines(corridor_loop, n=20) > 0
