"""The map's own depth frame (sim/simulator/map_depth.py) against the closed form of one
wall across the robot's path and the floor."""

from __future__ import annotations

import math

import numpy as np

from autonomy.camera import DepthCamera
from autonomy.raycast import SceneQuery
from autonomy.vectormap import VectorMap
from sim.simulator.map_depth import MapDepth
from tests.helpers import one_wall_depth

CAM = DepthCamera()


def test_a_wall_across_the_path_matches_the_closed_form() -> None:
    scene = SceneQuery(VectorMap(np.array([[2.5, -20.0, 2.5, 20.0]])))
    got = MapDepth(CAM).render(scene, np.zeros(3))
    want = one_wall_depth(CAM, 2.5)
    assert got.dtype == np.float32 and got.shape == want.shape
    both = (got > 0) & (want > 0)
    assert both.mean() > 0.5 and np.mean((got > 0) != (want > 0)) < 1e-3  # pixels at the range cuts may differ
    # The bearing table is 0.007 degrees fine: at 2.5 m the wall's depth is off by < 1 mm.
    assert np.max(np.abs(got[both] - want[both])) < 1e-3


def test_the_frame_turns_and_moves_with_the_pose() -> None:
    """The same wall seen from a pose moved and turned by the same amount is the same frame."""
    scene = SceneQuery(VectorMap(np.array([[2.5, -20.0, 2.5, 20.0]])))
    turned = SceneQuery(VectorMap(np.array([[1.0 - 20.0 * math.sin(0.7) + 2.5 * math.cos(0.7), 2.0 + 2.5 * math.sin(0.7) + 20.0 * math.cos(0.7),
                                             1.0 + 20.0 * math.sin(0.7) + 2.5 * math.cos(0.7), 2.0 + 2.5 * math.sin(0.7) - 20.0 * math.cos(0.7)]])))
    md = MapDepth(CAM)
    a = md.render(scene, np.zeros(3))
    b = md.render(turned, np.array([1.0, 2.0, 0.7]))
    both = (a > 0) & (b > 0)
    assert np.mean((a > 0) != (b > 0)) < 1e-3 and np.max(np.abs(a[both] - b[both])) < 2e-3
