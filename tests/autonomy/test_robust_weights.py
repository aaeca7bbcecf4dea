"""Robust weights in CGR's refinement: the Cauchy weights, the weighted moment matrix, and
a frame whose points seen past a pillar's corner are matched to the pillar's face."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.cgr import CGRConfig, CGRLocalizer
from autonomy.observation import (
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
