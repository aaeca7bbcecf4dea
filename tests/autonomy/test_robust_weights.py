"""Robust weights in CGR's refinement: the Cauchy weights, the weighted moment matrix, and
a frame whose points seen past a pillar's corner are matched to the pillar's face."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.localization.cgr import CGRConfig, CGRLocalizer
from autonomy.localization.observation import (
    ObservationConfig,
    correspond,
    line_frames,
    moments,
    moments_lever,
    robust_weights,
)
from tests.autonomy.test_localization import observe


def _random_frame(seed: int, n: int = 200) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Lines, a pose, points near the lines and their correspondences (some -1)."""
    rng = np.random.default_rng(seed)
    lines = rng.uniform(-5, 5, (6, 4))
    pose = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-math.pi, math.pi)])
    pts = rng.uniform(-4, 4, (n, 2))
    idx = rng.integers(-1, len(lines), n).astype(np.int64)
    return lines, pose, pts, idx


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.01, 2.0))
def test_robust_weights_match_the_closed_form(seed: int, scale: float) -> None:
    lines, pose, pts, idx = _random_frame(seed)
    frames = line_frames(lines, pose[0], pose[1])
    w = np.empty(len(pts))
    robust_weights(frames, idx, pose, pts, scale, w)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    world = pts @ np.array([[c, s], [-s, c]]) + pose[:2]
    for i, j in enumerate(idx):
        if j < 0:
            assert w[i] == 0.0
            continue
        d = frames[j, 0] * world[i, 0] + frames[j, 1] * world[i, 1] - frames[j, 2]
        assert w[i] == pytest.approx(1.0 / (1.0 + (d / scale) ** 2), rel=1e-12)
    # No scale: every used point weighs 1.
    robust_weights(frames, idx, pose, pts, 0.0, w)
    np.testing.assert_array_equal(w, (idx >= 0).astype(float))


@pytest.mark.parametrize("seed", range(5))
def test_weighted_moments_match_a_brute_force_sum(seed: int) -> None:
    lines, pose, pts, idx = _random_frame(seed)
    frames = line_frames(lines, pose[0], pose[1])
    w = np.random.default_rng(seed + 100).uniform(0, 1, len(pts))
    m = np.empty((5, 5))
    n = moments(frames, idx, pts, m, w)
    ref = np.zeros((5, 5))
    for i, j in enumerate(idx):
        if j < 0:
            continue
        nx, ny, c = frames[j]
        v = np.array([nx * pts[i, 0] + ny * pts[i, 1], ny * pts[i, 0] - nx * pts[i, 1], nx, ny, -c])
        ref += w[i] * np.outer(v, v)
    assert n == int((idx >= 0).sum())
    np.testing.assert_allclose(m, ref, rtol=1e-12, atol=1e-12)
    used = idx >= 0
    assert moments_lever(m) == pytest.approx(math.sqrt(np.sum(w[used] * np.sum(pts[used] ** 2, axis=1)) / w[used].sum()))
    # Unit weights and no weights are the same matrix.
    m1, m0 = np.empty((5, 5)), np.empty((5, 5))
    moments(frames, idx, pts, m1, np.ones(len(pts)))
    moments(frames, idx, pts, m0)
    np.testing.assert_array_equal(m1, m0)


#: A corridor 2.8 m wide whose upper wall is 0.84 degrees off parallel (a drawn plan), and a
#: pillar's face 0.25 m in front of the upper wall, ending at x = 2.5.
ANGLE = math.tan(math.radians(0.84))
SCENE = np.array(
    [
        [-10.0, -1.4, 10.0, -1.4],
        [2.8, 1.4 + 2.8 * ANGLE, 10.0, 1.4 + 10.0 * ANGLE],  # the upper wall, from where the scene lines resume
        [1.5, 1.15, 2.5, 1.15],  # the pillar's face
    ]
)
#: What the camera sees: the whole upper wall (it looks past the pillar's corner).
SEEN = np.array([[-10.0, -1.4, 10.0, -1.4], [-10.0, 1.4 - 10.0 * ANGLE, 10.0, 1.4 + 10.0 * ANGLE]])


def _past_the_corner(robust_scale: float, seed: int) -> tuple[float, float]:
    """A robot standing still for 3 s seeing 50 points of the upper wall between x = 2.55 and
    2.75, whose rays from the robot's centre cross the pillar's face first (the scene lines
    lack that piece of wall: the pillar hides it from where they were computed): how far
    the estimate moves (metres, degrees)."""
    rng = np.random.default_rng(seed)
    true = np.zeros(3)
    loc = CGRLocalizer(lambda x, y: SCENE, CGRConfig(robust_scale=robust_scale), ObservationConfig(), np.random.default_rng(seed))
    loc.reset(true, 0.02, math.radians(0.5))
    for _ in range(90):
        pts, nrm = observe(SEEN, true, rng, n=600, noise=0.005, lateral=0.01)
        keep = (pts[:, 0] > 2.0) & ((pts[:, 1] < 0) | (pts[:, 0] > 2.8))
        cx = rng.uniform(2.55, 2.75, 50)
        pts = np.vstack([pts[keep], np.column_stack([cx, 1.4 + ANGLE * cx])])
        nrm = np.vstack([nrm[keep], np.tile([0.0, -1.0], (50, 1))])
        loc.step(np.zeros(3), pts, nrm)
    est = loc.estimate().pose
    return math.hypot(est[0] - true[0], est[1] - true[1]), abs(math.degrees(est[2] - true[2]))


def test_the_corner_points_are_matched_to_the_pillar() -> None:
    """The premise: those points' rays meet the pillar's face first, 0.25 m in front of them."""
    pts = np.column_stack([np.linspace(2.55, 2.75, 5), 1.4 + ANGLE * np.linspace(2.55, 2.75, 5)])
    idx = np.empty(len(pts), dtype=np.int64)
    correspond(SCENE, np.zeros(3), pts, np.tile([0.0, -1.0], (5, 1)), True, math.cos(math.radians(35)), 0.5, idx)
    np.testing.assert_array_equal(idx, 2)


@pytest.mark.parametrize("seed", range(3))
def test_points_matched_to_the_wrong_line_do_not_move_the_estimate(seed: int) -> None:
    moved_m, turned_deg = _past_the_corner(1.0, seed)
    assert moved_m < 0.02 and turned_deg < 0.3
    # Squared distances (Eq. 1 as it stands): 50 points 0.25 m off turn the estimate by
    # 0.6-1 degree and move it 4-6 cm.
    moved_m, turned_deg = _past_the_corner(0.0, seed)
    assert moved_m > 0.035 and turned_deg > 0.5


def _second_round_weights(segs: np.ndarray, belief: np.ndarray, pts: np.ndarray, nrm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The correspondences at ``belief`` and the second round's weights of a wide belief
    (0.3 m, 2 degrees: the first round's scale is wide)."""
    loc = CGRLocalizer(lambda x, y: segs, CGRConfig(), ObservationConfig(), np.random.default_rng(0))
    idx = np.empty(len(pts), dtype=np.int64)
    correspond(segs, belief, pts, nrm, True, math.cos(math.radians(35)), 1.5, idx)
    frames = line_frames(segs, belief[0], belief[1])
    w = np.empty(len(pts))
    robust_weights(frames, idx, belief, pts, loc.robust_scale_m(0.3 + 4.0 * math.radians(2.0)), w)
    m = np.empty((5, 5))
    used = moments(frames, idx, pts, m, w)
    loc._reweigh(frames, idx, belief, pts, m, used, w)
    return idx, w


def _robot_frame(world: np.ndarray, pose: np.ndarray) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return (world - pose[:2]) @ np.array([[c, -s], [s, c]])


def test_the_second_round_drops_points_matched_to_a_line_behind_the_others() -> None:
    """58 points of a wall 4 m ahead and 14 whose rays, from a belief 5 cm off, pass the
    wall's end and meet a parallel line 0.69 m behind it: at the pose that fits them all
    best the 14 are still about 0.6 m off, the 58 within centimetres."""
    segs = np.array([[2.0, 0.0, 10.0, 0.0], [-2.0, 0.69, 1.98, 0.69]])
    true = np.array([4.0, -4.2, math.pi / 2])
    rng = np.random.default_rng(1)
    on_wall = np.column_stack([rng.uniform(2.3, 3.0, 58), 0.003 * rng.standard_normal(58)])
    past_end = np.column_stack([rng.uniform(2.0, 2.1, 14), 0.003 * rng.standard_normal(14)])
    pts = _robot_frame(np.vstack([on_wall, past_end]), true)
    nrm = np.tile([-1.0, 0.0], (72, 1))
    belief = true + [-0.15, 0.0, math.radians(0.7)]
    idx, w = _second_round_weights(segs, belief, pts, nrm)
    assert (idx[58:] == 1).sum() >= 10  # the premise: most of the 14 meet the line behind
    wrong = idx == 1
    assert w[wrong].max() < 0.1 and np.median(w[idx == 0]) > 0.5


def test_the_second_round_keeps_the_only_points_that_pin_a_direction() -> None:
    """A corridor whose walls pin only the across direction and a wall across its end
    3.5 m ahead; the belief is 0.25 m short along the corridor (odometry drift), so the end
    wall's points are 0.25 m off at the belief. They alone pin that direction: where
    everything fits best they fit too, and keep their weight."""
    segs = np.array([[-10.0, -1.0, 3.5, -1.0], [-10.0, 1.0, 3.5, 1.0], [3.5, -1.0, 3.5, 1.0]])
    true = np.zeros(3)
    rng = np.random.default_rng(2)
    pts, nrm = observe(segs, true, rng, n=600, noise=0.005, lateral=0.0)
    idx, w = _second_round_weights(segs, true - [0.25, 0.0, 0.0], pts, nrm)
    end = idx == 2
    assert end.sum() > 30 and np.median(w[end]) > 0.5
