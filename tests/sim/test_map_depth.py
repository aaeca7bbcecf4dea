"""The map's own depth frame (sim/simulator/map_depth.py) against the closed form of one
wall across the robot's path and the floor."""

from __future__ import annotations

import math

import numpy as np

from autonomy.maps.raycast import SceneQuery
from autonomy.maps.vectormap import VectorMap
from autonomy.perception.camera import DepthCamera
from sim.simulator.actors import Furniture
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


def test_clutter_is_seen_in_front_of_the_map() -> None:
    """A segment the map lacks, across the path nearer than the map's wall, is what the
    camera sees; a piece of furniture's outline is its footprint's four sides."""
    scene = SceneQuery(VectorMap(np.array([[2.5, -20.0, 2.5, 20.0]])))
    got = MapDepth(CAM).render(scene, np.zeros(3), clutter=np.array([[1.5, -20.0, 1.5, 20.0]]))
    want = one_wall_depth(CAM, 1.5)
    both = (got > 0) & (want > 0)
    assert both.mean() > 0.5 and np.max(np.abs(got[both] - want[both])) < 1e-3
    box = Furniture(kind="cabinet", x=2.0, y=1.0, yaw=math.pi / 2).outline()  # 0.9 x 0.45, turned 90 degrees
    assert box.shape == (4, 4)
    np.testing.assert_allclose(box[:, 2:], np.roll(box[:, :2], -1, axis=0))  # a closed loop
    np.testing.assert_allclose(np.sort(np.unique(np.round(box[:, 0], 9))), [1.775, 2.225])
    np.testing.assert_allclose(np.sort(np.unique(np.round(box[:, 1], 9))), [0.55, 1.45])
