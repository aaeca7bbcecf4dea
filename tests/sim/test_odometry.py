"""Odometry: exact without noise, multiplicative Gaussian noise with the configured spread."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.common.geometry import compose_pose, relative_pose
from sim.simulator.robot import Odometry, OdometryConfig

finite = st.floats(-50, 50, allow_nan=False)
angle = st.floats(-math.pi, math.pi, allow_nan=False)


@given(finite, finite, angle, finite, finite, angle)
def test_relative_and_compose_are_inverse(x0, y0, t0, x1, y1, t1) -> None:
    a, b = np.array([x0, y0, t0]), np.array([x1, y1, t1])
    c = compose_pose(a, relative_pose(a, b))
    np.testing.assert_allclose(c[:2], b[:2], atol=1e-9)
    assert math.cos(c[2] - b[2]) == pytest.approx(1.0, abs=1e-9)


def test_noiseless_odometry_integrates_the_true_path() -> None:
    odo = Odometry(OdometryConfig(0.0, 0.0), np.random.default_rng(0), np.array([1.0, 2.0, 0.3]))
    pose = np.array([1.0, 2.0, 0.3])
    for k in range(200):
        pose = compose_pose(pose, np.array([0.02, 0.005, 0.01 * math.sin(k / 10)]))
        odo.update(pose)
    np.testing.assert_allclose(odo.pose, pose, atol=1e-9)


def test_noise_is_multiplicative_with_the_configured_sigma() -> None:
    cfg = OdometryConfig(translation_noise=0.2, rotation_noise=0.1)
    odo = Odometry(cfg, np.random.default_rng(1), np.zeros(3))
    inc = np.array([0.03, 0.01, 0.02])
    pose = np.zeros(3)
    ratios = []
    for _ in range(4000):
        new = compose_pose(pose, inc)
        ratios.append(odo.update(new) / inc)
        pose = new
    r = np.array(ratios)
    np.testing.assert_allclose(r.mean(axis=0), 1.0, atol=0.02)
    np.testing.assert_allclose(r.std(axis=0), [0.2, 0.2, 0.1], rtol=0.08)


def test_bad_noise_is_an_error() -> None:
    with pytest.raises(InputError, match="translation_noise"):
        OdometryConfig(translation_noise=-0.1)
