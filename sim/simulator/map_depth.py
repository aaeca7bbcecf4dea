"""A depth frame of the map alone, in closed form: its walls as vertical planes and the
floor, seen through the camera's mount, with nothing the map lacks (no furniture, no
people, no noise).

What the robot's stack would see in an empty building, for tests and for measurements
that must separate the map's own ambiguity from clutter (``depthnav reloc-sample``).
A pixel's ray meets a wall where its horizontal part does: the horizontal distances are
ray-cast once per frame on a fine table of bearings (8192 across the image, 0.007
degrees apart for the Kinect) and looked up per pixel; a ray that points down meets the
floor where it crosses height 0.
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.maps.raycast import SceneQuery, rays_hit
from autonomy.perception.camera import DepthCamera, pixel_rays

TABLE_BEARINGS = 8192
"""Bearings ray-cast per frame, spread evenly over the image's horizontal field."""


class MapDepth:
    """Planar depth (float32 m, 0 outside the camera's range) of a map from a pose."""

    def __init__(self, camera: DepthCamera = DepthCamera()) -> None:  # noqa: B008
        self.camera = camera
        intr = camera.intrinsics
        self.shape = (intr.height, intr.width)
        rays = pixel_rays(intr).reshape(-1, 3) @ camera.mount.rotation().T  # robot frame, per unit of depth
        self._bearing = np.arctan2(rays[:, 1], rays[:, 0])
        self._h_per_depth = np.hypot(rays[:, 0], rays[:, 1])
        with np.errstate(divide="ignore"):
            self._to_floor = np.where(rays[:, 2] < 0, -camera.mount.translation()[2] / rays[:, 2], np.inf)
        self._table = np.linspace(self._bearing.min(), self._bearing.max(), TABLE_BEARINGS)
        self._index = np.rint((self._bearing - self._table[0]) / (self._table[1] - self._table[0])).astype(np.int64)

    def render(self, scene: SceneQuery, pose: np.ndarray, clutter: np.ndarray | None = None) -> np.ndarray:
        """The frame the camera sees from ``pose`` (x, y, yaw) on ``scene``'s map;
        ``clutter``: (K, 4) segments the map lacks, seen as walls too (furniture as the
        full-height faces of its footprint, :meth:`sim.simulator.actors.Furniture.outline`)."""
        cam = self.camera
        c, s = math.cos(pose[2]), math.sin(pose[2])
        t = cam.mount.translation()
        ox, oy = pose[0] + c * t[0] - s * t[1], pose[1] + s * t[0] + c * t[1]
        a = self._table + pose[2]
        lines = scene.scene_lines(ox, oy)[0]
        if clutter is not None and len(clutter):
            lines = np.vstack([lines, np.asarray(clutter, dtype=np.float64).reshape(-1, 4)])
        idx, dist = rays_hit(lines, ox, oy, np.column_stack([np.cos(a), np.sin(a)]))
        dist = np.where(idx >= 0, dist, np.inf)
        z = np.minimum(dist[self._index] / self._h_per_depth, self._to_floor)
        z = np.where((z >= cam.min_range_m) & (z <= cam.max_range_m), z, 0.0)
        return z.reshape(self.shape).astype(np.float32)
