"""Open path lengths and direction choice (BV2012, Eq. 3-5) against brute-force references."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from autonomy.common.errors import InputError
from autonomy.navigation.avoidance import (
    AvoidanceConfig,
    AvoidanceResult,
    candidate_angles,
    choose_direction,
    obstacle_points,
    open_path_lengths,
)


def _reference_lengths(points: np.ndarray, angles: np.ndarray, r: float, max_range: float) -> np.ndarray:
    """Eq. 3-4 written out literally: distance to the ray's line by vector rejection."""
    out = np.full(len(angles), max_range)
    for k, th in enumerate(angles):
        t = np.array([math.cos(th), math.sin(th)])
        along = points @ t
        rejection = points - along[:, None] * t[None, :]
        in_corridor = np.linalg.norm(rejection, axis=1) < r  # Eq. 3
        ahead = along > 0
        sel = in_corridor & ahead
        if sel.any():
            out[k] = min(max_range, float(np.min(np.maximum(0.0, along[sel] - r))))  # Eq. 4
    return out


def _wall(x: float, y0: float, y1: float, step: float = 0.01, gap: tuple[float, float] | None = None) -> np.ndarray:
    """Points on the line x = const from y0 to y1, optionally without the open interval ``gap``."""
    ys = np.arange(y0, y1 + 0.5 * step, step)
    if gap is not None:
        ys = ys[(ys <= gap[0]) | (ys >= gap[1])]
    return np.column_stack([np.full_like(ys, x), ys])


# --- Eq. 3-4 kernel -----------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, 10**6),
    st.integers(0, 300),
    st.floats(0.05, 1.0),
    st.floats(0.5, 8.0),
)
def test_kernel_matches_bruteforce(seed: int, n: int, r: float, max_range: float) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-5, 5, size=(n, 2))
    angles = rng.uniform(-math.pi, math.pi, size=37)
    got = open_path_lengths(pts, angles, r, max_range)
    np.testing.assert_allclose(got, _reference_lengths(pts, angles, r, max_range), rtol=0, atol=1e-12)


def test_empty_cloud_is_max_range_everywhere() -> None:
    angles = np.linspace(-1, 1, 11)
    np.testing.assert_array_equal(open_path_lengths(np.zeros((0, 2)), angles, 0.4, 4.0), np.full(11, 4.0))


@pytest.mark.parametrize("D", [0.8, 1.5, 3.0])
def test_wall_ahead(D: float) -> None:
    r = 0.4
    d = open_path_lengths(_wall(D, -2, 2), np.array([0.0]), r, 10.0)
    assert d[0] == pytest.approx(D - r)


def test_wall_beyond_range_is_capped() -> None:
    assert open_path_lengths(_wall(6.0, -2, 2), np.array([0.0]), 0.4, 4.0)[0] == 4.0


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_point_beside_the_path(side: float) -> None:
    r = 0.4
    clear = open_path_lengths(np.array([[1.5, side * 0.45]]), np.array([0.0]), r, 4.0)[0]
    hit = open_path_lengths(np.array([[1.5, side * 0.35]]), np.array([0.0]), r, 4.0)[0]
    assert clear == 4.0
    assert hit == pytest.approx(1.5 - r)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10**6), st.integers(1, 200))
def test_points_behind_never_block_forward(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    pts = np.column_stack([-rng.uniform(0, 3, n), rng.uniform(-3, 3, n)])
    pts[0] = [-0.1, 0.05]  # inside the robot's radius, behind
    cfg = AvoidanceConfig()
    assert open_path_lengths(pts, np.array([0.0]), cfg.radius_m, cfg.max_range_m)[0] == cfg.max_range_m
    res = choose_direction(pts, 0.0, cfg)
    assert res.theta_star == 0.0 and not res.blocked and res.open_length_m == cfg.max_range_m


def test_point_inside_the_robot_blocks_towards_it_not_away() -> None:
    cfg = AvoidanceConfig()
    pts = np.array([[0.2, 0.0]])
    towards = choose_direction(pts, 0.0, cfg)
    assert towards.blocked and towards.safe_speed_mps == 0.0
    assert np.all(towards.lengths == 0.0) and towards.theta_star == 0.0  # tie -> desired
    away = choose_direction(pts, math.pi, cfg)
    assert not away.blocked and away.open_length_m == cfg.max_range_m


# --- Eq. 5 and the candidate fan ----------------------------------------------------------


@pytest.mark.parametrize("desired", [0.0, 0.7, -1.2, 3.0, -math.pi, math.pi])
def test_nothing_in_the_way(desired: float) -> None:
    cfg = AvoidanceConfig()
    res = choose_direction(np.zeros((0, 2)), desired, cfg)
    assert isinstance(res, AvoidanceResult)
    assert math.cos(res.theta_star - desired) == pytest.approx(1.0)
    assert res.open_length_m == cfg.max_range_m and not res.blocked
    assert res.safe_speed_mps == pytest.approx(math.sqrt(2 * cfg.max_decel_mps2 * (cfg.max_range_m - cfg.stop_distance_m)))


@pytest.mark.parametrize("desired", [0.0, 0.3, -2.0, 2.9, math.pi, -3.1, 7.0])
def test_candidate_fan(desired: float) -> None:
    cfg = AvoidanceConfig(n_directions=31)
    a = candidate_angles(desired, cfg)
    wrapped = math.atan2(math.sin(desired), math.cos(desired))
    assert a.shape == (31,)
    assert np.all(np.diff(a) > 0)
    assert a[0] >= -math.pi and a[-1] <= math.pi
    assert a[-1] - a[0] <= cfg.fov_rad + 1e-12
    assert np.min(np.abs(np.cos(a - wrapped) - 1.0)) < 1e-12  # desired is a candidate
    assert np.all(np.cos(a - wrapped) >= math.cos(cfg.fov_rad / 2) - 1e-12)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10**6), st.floats(-3.0, 3.0))
def test_choice_maximises_eq5(seed: int, desired: float) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-4, 4, size=(150, 2))
    cfg = AvoidanceConfig()
    res = choose_direction(pts, desired, cfg)
    ref = _reference_lengths(pts, res.angles, cfg.robot_radius_m + cfg.safety_margin_m, cfg.max_range_m)
    np.testing.assert_allclose(res.lengths, ref, atol=1e-12)
    score = ref * np.cos(res.angles - desired)
    assert score[res.best_index] >= score.max() - 1e-9
    assert res.theta_star == res.angles[res.best_index]
    assert res.open_length_m == res.lengths[res.best_index]


def _ray_clearance_through_wall(theta: float, x_wall: float, gap: tuple[float, float]) -> float:
    """Perpendicular clearance between the ray's line and the nearer gap edge where it crosses x_wall."""
    y = x_wall * math.tan(theta)
    return min(y - gap[0], gap[1] - y) * math.cos(theta)


def test_wide_gap_is_chosen_over_the_wall() -> None:
    cfg = AvoidanceConfig()  # r = 0.4, so the corridor is 0.8 wide
    D, gap = 2.0, (0.2, 1.4)  # 1.2 m gap left of straight ahead
    res = choose_direction(_wall(D, -3, 3, gap=gap), 0.0, cfg)
    assert res.open_length_m * math.cos(res.theta_star) > D  # the open length runs past the wall
    assert res.theta_star > 0
    assert _ray_clearance_through_wall(res.theta_star, D, gap) >= cfg.radius_m - 0.01
    assert not res.blocked


def test_a_horizon_keeps_the_desired_way_over_a_longer_one() -> None:
    """A wall 1.8 m straight ahead, open 4 m on both diagonals: Eq. 5 prefers a diagonal;
    with open lengths scored up to 1 m, straight ahead wins, at the speed its full open
    length allows."""
    cfg = AvoidanceConfig()
    pts = _wall(1.8 + cfg.radius_m, -0.6, 0.6)
    res = choose_direction(pts, 0.0, cfg)
    assert abs(res.theta_star) > 0.3
    capped = choose_direction(pts, 0.0, cfg, horizon_m=1.0)
    assert capped.theta_star == 0.0
    assert capped.open_length_m == pytest.approx(1.8, abs=0.02)
    assert capped.safe_speed_mps == pytest.approx(math.sqrt(2 * cfg.max_decel_mps2 * (capped.open_length_m - cfg.stop_distance_m)))
    # With nothing in range the desired direction wins either way.
    assert choose_direction(np.zeros((0, 2)), 0.2, cfg, horizon_m=1.0).theta_star == choose_direction(np.zeros((0, 2)), 0.2, cfg).theta_star == pytest.approx(0.2)


def test_narrow_gap_is_not_taken() -> None:
    cfg = AvoidanceConfig()
    D, gap = 2.0, (0.5, 1.1)  # 0.6 m < 2 r = 0.8 m
    pts = _wall(D, -3, 3, gap=gap)
    res = choose_direction(pts, 0.0, cfg)
    # every candidate stops short of where its ray meets the wall line (at D / cos(theta))
    assert np.all(res.lengths * np.cos(res.angles) < D - cfg.radius_m + 0.1)
    assert res.open_length_m * math.cos(res.theta_star) < D


def test_tie_goes_to_the_direction_closest_to_desired() -> None:
    cfg = AvoidanceConfig()
    res = choose_direction(np.array([[0.1, 0.0], [0.05, 0.2], [0.05, -0.2]]), 0.25, cfg)
    assert np.all(res.lengths == 0.0)
    assert res.theta_star == pytest.approx(0.25) and res.blocked


# --- safe speed ---------------------------------------------------------------------------


def _stopping_distance(v0: float, a: float, dt: float = 1e-4) -> float:
    """Distance covered braking from v0 at constant deceleration a, stepped in time."""
    s, v = 0.0, v0
    while v > 0:
        v_new = max(0.0, v - a * dt)
        s += 0.5 * (v + v_new) * dt
        v = v_new
    return s


@settings(max_examples=25, deadline=None)
@given(st.floats(0.5, 4.0), st.floats(0.3, 3.0), st.floats(-0.3, 0.3))
def test_safe_speed_stops_before_the_obstacle(D: float, decel: float, y_off: float) -> None:
    cfg = AvoidanceConfig(max_decel_mps2=decel, fov_rad=math.radians(10))
    pts = _wall(D, -3, 3) + np.array([0.0, y_off])
    res = choose_direction(pts, 0.0, cfg)
    s = _stopping_distance(res.safe_speed_mps, decel)
    assert s <= max(0.0, res.open_length_m - cfg.stop_distance_m) + 1e-3
    t = np.array([math.cos(res.theta_star), math.sin(res.theta_star)])
    centre = s * t
    assert np.min(np.linalg.norm(pts - centre, axis=1)) >= cfg.robot_radius_m  # the body never touches
    # and it is the largest such speed: 5% faster overshoots the reserved stop distance
    if res.open_length_m > cfg.stop_distance_m:
        assert _stopping_distance(1.05 * res.safe_speed_mps, decel) > res.open_length_m - cfg.stop_distance_m


def test_blocked_when_within_stop_distance() -> None:
    cfg = AvoidanceConfig(fov_rad=math.radians(20))
    res = choose_direction(_wall(cfg.radius_m + 0.03, -3, 3), 0.0, cfg)
    assert res.blocked and res.safe_speed_mps == 0.0


# --- obstacle_points ----------------------------------------------------------------------


def test_obstacle_points_height_band() -> None:
    cfg = AvoidanceConfig(min_height_m=0.05, max_height_m=1.1)
    pts = np.array(
        [
            [1.0, 0.0, 0.0],  # floor
            [1.1, 0.1, 0.02],  # floor noise
            [1.2, 0.2, 0.05],  # band edge: kept
            [1.3, 0.3, 0.5],  # obstacle
            [1.4, 0.4, 1.1],  # band edge: kept
            [1.5, 0.5, 1.5],  # overhead
            [1.6, 0.6, np.nan],  # invalid
        ]
    )
    out = obstacle_points(pts, cfg)
    np.testing.assert_array_equal(out, [[1.2, 0.2], [1.3, 0.3], [1.4, 0.4]])
    assert obstacle_points(np.zeros((0, 3)), cfg).shape == (0, 2)
    # A second cloud is taken after the first, as if stacked.
    np.testing.assert_array_equal(obstacle_points(pts[:3], cfg, also=pts[3:]), out)


@given(arrays(np.float64, st.tuples(st.integers(0, 40), st.just(3)), elements=st.sampled_from([0.0, 0.05, 0.3, 1.1, 2.0, -1.0, np.nan, np.inf])),
       st.integers(0, 40))
def test_obstacle_points_match_a_numpy_mask(pts: np.ndarray, split: int) -> None:
    cfg = AvoidanceConfig(min_height_m=0.05, max_height_m=1.1)
    z = pts[:, 2]
    keep = (z >= cfg.min_height_m) & (z <= cfg.max_height_m) & np.isfinite(pts).all(axis=1)
    k = min(split, len(pts))
    np.testing.assert_array_equal(obstacle_points(pts[:k], cfg, also=pts[k:]), pts[keep, :2])


def test_obstacle_points_feed_choose_direction() -> None:
    cfg = AvoidanceConfig()
    table_top = np.column_stack([np.full(50, 1.5), np.linspace(-1, 1, 50), np.full(50, 1.5)])
    floor = np.column_stack([np.linspace(0.5, 3, 50), np.zeros(50), np.zeros(50)])
    res = choose_direction(obstacle_points(np.vstack([table_top, floor]), cfg), 0.0, cfg)
    assert res.theta_star == 0.0 and res.open_length_m == cfg.max_range_m


# --- bad input ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs",
    [
        {"robot_radius_m": 0.0},
        {"robot_radius_m": -0.3},
        {"robot_radius_m": float("nan")},
        {"safety_margin_m": -0.1},
        {"max_range_m": 0.0},
        {"max_range_m": float("inf")},
        {"n_directions": 0},
        {"n_directions": 2.5},
        {"n_directions": True},
        {"fov_rad": 0.0},
        {"fov_rad": 7.0},
        {"min_height_m": 1.2, "max_height_m": 1.1},
        {"stop_distance_m": -0.01},
        {"max_decel_mps2": 0.0},
        {"robot_radius_m": "0.3"},
    ],
)
def test_bad_config(kwargs: dict) -> None:
    with pytest.raises(InputError):
        AvoidanceConfig(**kwargs)


def test_bad_arguments() -> None:
    with pytest.raises(InputError):
        obstacle_points(np.zeros((4, 2)))
    with pytest.raises(InputError):
        open_path_lengths(np.zeros((4, 3)), np.zeros(3), 0.4, 4.0)
    with pytest.raises(InputError):
        open_path_lengths(np.zeros((4, 2)), np.zeros(3), -0.4, 4.0)
    with pytest.raises(InputError):
        open_path_lengths(np.zeros((4, 2)), np.zeros(3), 0.4, 0.0)
    with pytest.raises(InputError):
        choose_direction(np.zeros((4, 2)), float("nan"))


# --- benchmark (not timed-asserted) -------------------------------------------------------


def benchmark_avoidance(n_points: int = 4000, repeats: int = 50) -> float:
    """Median milliseconds of choose_direction on a random n-point cloud (default config)."""
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(0.3, 4.0, n_points), rng.uniform(-2.0, 2.0, n_points)])
    cfg = AvoidanceConfig()
    choose_direction(pts, 0.1, cfg)  # compile / load the cache
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        choose_direction(pts, 0.1, cfg)
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def test_benchmark_runs() -> None:
    ms = benchmark_avoidance(n_points=500, repeats=3)
    assert math.isfinite(ms) and ms > 0


if __name__ == "__main__":
    print(f"choose_direction on 4000 points: {benchmark_avoidance():.3f} ms (median)")
