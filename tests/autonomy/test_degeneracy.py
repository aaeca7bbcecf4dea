"""The degeneracy-aware refinement: eigen-directions, their bias gain, and CGR on a
corridor whose walls are nearly parallel (a drawn floor plan) seen with a small bias."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from autonomy.localization.cgr import CGRConfig, CGRLocalizer
from autonomy.localization.observation import (
    ObservationConfig,
    correspond,
    jacobi_eigh3,
    line_frames,
    trusted_directions,
)
from tests.autonomy.test_localization import observe


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=6, max_size=6),
    st.lists(st.floats(-6, 6), min_size=3, max_size=3),
)
@example([0.0, 0.0, 1.9308228994945364e-168, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0])  # squares underflow
@example([0.0, 0.0, 0.0, 0.0, 0.0, 2.2250738585e-313], [0.0, 0.0, 0.0])  # a subnormal largest entry
def test_jacobi_eigh3_matches_lapack(entries: list[float], log_scale: list[float]) -> None:
    a = np.array([[entries[0], entries[1], entries[2]], [entries[1], entries[3], entries[4]], [entries[2], entries[4], entries[5]]])
    d = np.diag(10.0 ** np.array(log_scale))
    a = d @ a @ d  # badly scaled, as pose curvatures in metres and radians are
    vecs = np.empty((3, 3))
    w = jacobi_eigh3(a, vecs)
    scale = max(np.abs(a).max(), 1e-300)
    np.testing.assert_allclose(np.sort(w), np.linalg.eigvalsh(a), atol=1e-12 * scale)
    np.testing.assert_allclose(vecs.T @ vecs, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(a @ vecs, vecs * w, atol=1e-11 * scale)


def _corridor(angle_deg: float, far_wall: bool = False) -> np.ndarray:
    """Two walls 2 m apart along x, the upper one turned by ``angle_deg`` (a drawn plan's
    walls are rarely exactly parallel); optionally a wall across the corridor at x = 3.5."""
    a = math.tan(math.radians(angle_deg))
    segs = [[-10.0, -1.0, 10.0, -1.0], [-10.0, 1.0 - 10 * a, 10.0, 1.0 + 10 * a]]
    if far_wall:
        segs.append([3.5, -3.0, 3.5, 3.0])
    return np.array(segs)


def _reference_gains(segs: np.ndarray, pose: np.ndarray, pts: np.ndarray, idx: np.ndarray, lever: float) -> tuple[np.ndarray, np.ndarray]:
    """Independent reference: the Jacobian rows in scaled pose coordinates, LAPACK's
    eigenvectors, and each one's bias gain sum |J v| / sum (J v)^2."""
    frames = line_frames(segs, pose[0], pose[1])
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rows = []
    for p, j in zip(pts, idx, strict=True):
        if j < 0:
            continue
        r = np.array([c * p[0] - s * p[1], s * p[0] + c * p[1]])
        n = frames[j, :2]
        rows.append([n[0], n[1], (n[1] * r[0] - n[0] * r[1]) / lever])
    jac = np.array(rows)
    _, vecs = np.linalg.eigh(jac.T @ jac)
    proj = jac @ vecs
    return vecs, np.abs(proj).sum(axis=0) / (proj**2).sum(axis=0)


def _frame(segs: np.ndarray, pose: np.ndarray, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    pts, nrm = observe(segs, pose, np.random.default_rng(seed), n=600, noise=0.0, lateral=0.0)
    idx = np.empty(len(pts), dtype=np.int64)
    correspond(segs, pose, pts, nrm, True, math.cos(math.radians(35)), 0.5, idx)
    lever = math.sqrt(float(np.mean(np.sum(pts[idx >= 0] ** 2, axis=1))))
    return pts, nrm, idx, lever


@pytest.mark.parametrize(("angle", "far", "expected"), [(0.84, False, 2), (0.84, True, 3)])
def test_trusted_directions_match_the_reference_gains(angle: float, far: bool, expected: int) -> None:
    segs = _corridor(angle, far)
    pose = np.array([0.0, 0.0, 0.0])
    pts, _, idx, lever = _frame(segs, pose)
    proj = np.empty((3, 3))
    k = trusted_directions(line_frames(segs, 0.0, 0.0), idx, pose, pts, lever, 8.0, proj)
    vecs, gains = _reference_gains(segs, pose, pts, idx, lever)
    assert k == int((gains <= 8.0).sum()) == expected
    # The projector in scaled coordinates is the sum of the trusted eigenvectors' outer products.
    ref = sum(np.outer(v, v) for v, g in zip(vecs.T, gains, strict=True) if g <= 8.0)
    scale = np.diag([1.0, 1.0, lever])
    np.testing.assert_allclose(scale @ proj @ np.linalg.inv(scale), ref, atol=1e-9)


def test_nearly_parallel_walls_leave_the_corridor_axis_untrusted() -> None:
    """0.84 degrees between the walls (GHC5's median between neighbouring walls): the
    gain along the corridor is about 1 / 0.0147 rad, so that axis is projected out; a
    step across the corridor or in heading passes unchanged."""
    segs = _corridor(0.84)
    pose = np.zeros(3)
    pts, _, idx, lever = _frame(segs, pose)
    proj = np.empty((3, 3))
    trusted_directions(line_frames(segs, 0.0, 0.0), idx, pose, pts, lever, 8.0, proj)
    assert abs((proj @ [1.0, 0.0, 0.0])[0]) < 1e-3
    np.testing.assert_allclose(proj @ [0.0, 1.0, 0.0], [0.0, 1.0, 0.0], atol=1e-2)
    # Off: the identity.
    trusted_directions(line_frames(segs, 0.0, 0.0), idx, pose, pts, lever, 0.0, proj)
    np.testing.assert_array_equal(proj, np.eye(3))


def _biased_corridor_drift(max_gain: float, seed: int) -> float:
    """A robot standing still for 10 s between walls 0.84 degrees from parallel whose
    faces it sees 1 cm in front of their map lines: how far the estimate slides along."""
    segs = _corridor(0.84)
    true = np.array([0.0, 0.0, 0.0])
    rng = np.random.default_rng(seed)
    loc = CGRLocalizer(lambda x, y: segs, CGRConfig(degeneracy_max_gain=max_gain), ObservationConfig(), np.random.default_rng(seed))
    loc.reset(true, 0.01, math.radians(0.2))
    for _ in range(300):
        pts, nrm = observe(segs, true, rng, noise=0.005)
        pts = pts + 0.01 * nrm  # the normals face the robot: the seen face is 1 cm nearer
        loc.step(np.zeros(3), pts, nrm)
    return abs(float(loc.estimate().pose[0] - true[0]))


@pytest.mark.parametrize("seed", range(3))
def test_a_small_bias_does_not_slide_the_estimate_along_a_corridor(seed: int) -> None:
    assert _biased_corridor_drift(8.0, seed) < 0.03
    # Every direction trusted: the estimate slides towards the biased optimum, about
    # 0.68 m along the corridor.
    assert _biased_corridor_drift(0.0, seed) > 0.5
