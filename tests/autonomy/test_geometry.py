"""The shared plane-geometry helpers (autonomy/common/geometry.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.geometry import (
    compose_pose,
    crosses_any,
    point_segment_distance,
    point_segment_projection,
    points_from_frame,
    points_in_frame,
    polyline_clear,
    relative_pose,
    segments_cross_nb,
    segments_near_points,
    sensor_view,
    wrap_angle,
    wrap_angle_nb,
    wrap_angles,
)


@pytest.mark.parametrize("a", [0.0, 1.0, -1.0, math.pi - 1e-9, 3 * math.pi + 0.5, -7.5, 100.0])
def test_wrap_angle_lands_in_minus_pi_pi_on_the_same_direction(a: float) -> None:
    w = wrap_angle(a)
    assert -math.pi <= w <= math.pi
    assert math.cos(w) == pytest.approx(math.cos(a), abs=1e-12) and math.sin(w) == pytest.approx(math.sin(a), abs=1e-12)
    assert wrap_angle_nb(a) == w
    assert wrap_angles(np.array([a]))[0] == pytest.approx(w, abs=1e-15)


def test_relative_and_compose_pose_are_inverse() -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        a = np.array([*rng.normal(0, 5, 2), rng.uniform(-math.pi, math.pi)])
        b = np.array([*rng.normal(0, 5, 2), rng.uniform(-math.pi, math.pi)])
        c = compose_pose(a, relative_pose(a, b))
        assert c[:2] == pytest.approx(b[:2], abs=1e-9)
        assert wrap_angle(c[2] - b[2]) == pytest.approx(0.0, abs=1e-12)


def _brute_distance(p: np.ndarray, seg: np.ndarray) -> float:
    s = np.linspace(0.0, 1.0, 20001)
    q = seg[:2] + s[:, None] * (seg[2:] - seg[:2])
    return float(np.min(np.hypot(q[:, 0] - p[0], q[:, 1] - p[1])))


def test_point_segment_distance_against_dense_sampling() -> None:
    rng = np.random.default_rng(1)
    segs = rng.normal(0, 2, (12, 4))
    segs[3, 2:] = segs[3, :2]  # a zero-length segment is its end point
    pts = rng.normal(0, 3, (5, 2))
    got = point_segment_distance(pts, segs)
    assert got.shape == (5, 12)
    for i, p in enumerate(pts):
        one = point_segment_distance(p, segs)
        assert np.array_equal(one, got[i])  # a point alone gives the same numbers, bit for bit
        for j, seg in enumerate(segs):
            assert one[j] == pytest.approx(_brute_distance(p, seg), abs=1e-3)
    t, d = point_segment_projection(pts[0], segs)
    assert np.array_equal(d, got[0]) and ((t >= 0) & (t <= 1)).all() and t[3] == 0.0


@pytest.mark.parametrize(
    ("seg", "want"),
    [
        ((0.0, -1.0, 0.0, 1.0), True),  # crosses
        ((0.0, 0.5, 0.0, 1.0), False),  # beside
        ((1.0, -1.0, 1.0, 1.0), False),  # touches the end: not a proper crossing
        ((-1.0, 0.0, 0.5, 0.0), False),  # collinear
    ],
)
def test_crossing_is_proper_and_the_kernel_agrees(seg: tuple[float, ...], want: bool) -> None:
    p, q = np.array([-1.0, 0.0]), np.array([1.0, 0.0])
    assert crosses_any(p, q, np.array([seg])) is want
    assert segments_cross_nb(p[0], p[1], q[0], q[1], *seg) is want


@given(st.tuples(*[st.floats(-20, 20)] * 2, st.floats(-4, 4)), st.lists(st.tuples(st.floats(-20, 20), st.floats(-20, 20)), min_size=1, max_size=20))
def test_points_in_frame_undo_compose_pose_and_points_from_frame_redo_it(pose, pts) -> None:
    pose, pts = np.array(pose), np.array(pts)
    local = points_in_frame(pose, pts)
    assert local.flags.c_contiguous and local.shape == pts.shape
    back = np.array([compose_pose(pose, np.array([q[0], q[1], 0.0]))[:2] for q in local])
    np.testing.assert_allclose(back, pts, atol=1e-9)
    np.testing.assert_allclose(points_from_frame(pose, local), pts, atol=1e-9)
    direct = np.array([compose_pose(pose, np.array([q[0], q[1], 0.0]))[:2] for q in pts])
    np.testing.assert_allclose(points_from_frame(pose, pts), direct, atol=1e-9)


@given(st.tuples(*[st.floats(-20, 20)] * 2, st.floats(-4, 4)), st.tuples(st.floats(-1, 1), st.floats(-1, 1)),
       st.lists(st.tuples(st.floats(-10, 10), st.floats(-10, 10)), min_size=1, max_size=10))
def test_a_sensor_sees_the_same_world_points_from_where_it_sits(pose, sensor, pts) -> None:
    """The sensor's pose and the points relative to it put every point where the robot's
    pose and the robot-frame points do; the sensor sits at ``sensor`` in the robot frame."""
    pose, pts = np.array(pose), np.array(pts)
    at, rel = sensor_view(pose, pts, np.array(sensor))
    assert rel.flags.c_contiguous and rel.shape == pts.shape
    np.testing.assert_allclose(points_from_frame(at, rel), points_from_frame(pose, pts), atol=1e-9)
    np.testing.assert_allclose(at[:2], points_from_frame(pose, np.array([sensor]))[0], atol=1e-12)
    assert wrap_angle(float(at[2] - pose[2])) == pytest.approx(0.0, abs=1e-12)


coord = st.floats(-5, 5, allow_nan=False)


@settings(max_examples=200)
@given(
    st.lists(st.tuples(coord, coord), min_size=2, max_size=6),
    st.lists(st.tuples(coord, coord), min_size=1, max_size=15),
    st.floats(0.1, 12.0),
    st.floats(0.05, 1.0),
)
def test_polyline_clear_against_dense_sampling(path, pts, length, clearance) -> None:
    """The first ``length`` of the path, sampled every millimetre, against each point."""
    path, pts = np.array(path), np.array(pts)
    seg_len = np.hypot(*np.diff(path, axis=0).T)
    s = np.arange(0.0, min(length, seg_len.sum()) + 1e-12, 0.001)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg_len) - 1)
    f = np.where(seg_len[k] > 0, (s - cum[k]) / np.where(seg_len[k] > 0, seg_len[k], 1.0), 0.0)
    samples = path[k] + f[:, None] * (path[k + 1] - path[k])
    d = np.min(np.hypot(samples[:, None, 0] - pts[None, :, 0], samples[:, None, 1] - pts[None, :, 1]))
    if abs(d - clearance) > 2e-3:  # the sampling's resolution
        assert polyline_clear(path, pts, length, clearance) == (d > clearance)


def test_polyline_clear_without_points_or_path_is_clear() -> None:
    assert polyline_clear(np.array([[0.0, 0.0], [1.0, 0.0]]), np.zeros((0, 2)), 1.0, 0.3)
    assert polyline_clear(np.array([[0.0, 0.0]]), np.array([[0.0, 0.0]]), 1.0, 0.3)
    # A point beyond the length checked does not count.
    assert polyline_clear(np.array([[0.0, 0.0], [10.0, 0.0]]), np.array([[5.0, 0.0]]), 3.0, 0.3)
    assert not polyline_clear(np.array([[0.0, 0.0], [10.0, 0.0]]), np.array([[2.9, 0.1]]), 3.0, 0.3)


@settings(max_examples=200)
@given(
    st.lists(st.tuples(*[st.floats(-5, 5)] * 4), min_size=1, max_size=12),
    st.lists(st.tuples(st.floats(-6, 6), st.floats(-6, 6)), min_size=0, max_size=30),
    st.floats(0.01, 2.0),
)
def test_segments_near_points_against_brute_distance(segs, pts, tol) -> None:
    """Per segment, any point closer than ``tol``: against each point's distance to the
    segment sampled densely (zero-length segments included)."""
    segs, pts = np.array(segs).reshape(-1, 4), np.array(pts).reshape(-1, 2)
    got = segments_near_points(segs, pts, tol)
    assert got.shape == (len(segs),) and got.dtype == bool
    for k, seg in enumerate(segs):
        d = min((_brute_distance(p, seg) for p in pts), default=math.inf)
        if abs(d - tol) > 2e-3:  # the sampling's resolution
            assert bool(got[k]) == (d < tol)


def test_segments_near_points_computes_its_documented_expression_bit_for_bit() -> None:
    """The kernel's distances are the docstring's expression in numpy, to the last bit:
    with ``tol`` set to one of those distances exactly, ``<`` decides the same way."""
    rng = np.random.default_rng(3)
    for _ in range(300):
        segs, pts = rng.uniform(-3, 3, (int(rng.integers(1, 40)), 4)), rng.uniform(-4, 4, (int(rng.integers(1, 80)), 2))
        segs[: len(segs) // 3, 2:] = segs[: len(segs) // 3, :2]
        a, d = segs[None, :, :2], segs[None, :, 2:] - segs[None, :, :2]
        r = pts[:, None, :] - a
        s = np.clip(np.einsum("mkj,mkj->mk", r, d) / np.maximum(np.einsum("mkj,mkj->mk", d, d), 1e-12), 0.0, 1.0)
        gap = np.hypot(r[..., 0] - s * d[..., 0], r[..., 1] - s * d[..., 1])
        tol = float(gap.ravel()[rng.integers(gap.size)])
        assert np.array_equal(segments_near_points(segs, pts, tol), (gap < tol).any(axis=0))
    assert not segments_near_points(np.zeros((2, 4)), np.zeros((0, 2)), 1.0).any()
    assert segments_near_points(np.zeros((0, 4)), np.zeros((3, 2)), 1.0).shape == (0,)
