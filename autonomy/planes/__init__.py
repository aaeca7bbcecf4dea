"""Plane-based 3D mapping (PlaneMap): multi-plane RANSAC, randomized Hough, octree map.

Pipeline for one depth frame (see docs/mapping.md):

1. :func:`depth_to_cloud` — valid pixels to points in a sensor-centred frame with z up
   (pass the rotation part of world_from_camera, optical frame);
2. :func:`ransac_planes` or :func:`hough_planes` — up to 8 planes with their inliers and
   boundaries (:class:`PlaneDetection`);
3. :func:`register_planes` — the planes moved to the world frame by the camera position
   and inserted into a :class:`PlaneOctree` at their centre points.

:func:`detection_frame` gives both transforms for a camera on a robot at a planar pose.
"""

from __future__ import annotations

import numpy as np

from autonomy.planes.boundary import hull_2d, plane_basis, plane_hull, polygon_area, to_plane_coords
from autonomy.planes.geometry import (
    Plane,
    PlaneDetection,
    angle_between_planes_deg,
    depth_to_cloud,
    fit_plane,
    plane_spherical,
    spherical_normal,
)
from autonomy.planes.hough import (
    HoughConfig,
    SparseAccumulator,
    accumulator_nbytes,
    dense_accumulator_nbytes,
    hough_planes,
)
from autonomy.planes.octree import (
    POLICIES,
    Leaf,
    MapPlane,
    OctreeConfig,
    PatchArrays,
    PlaneOctree,
)
from autonomy.planes.ransac import RansacConfig, ransac_planes

METHODS = ("ransac", "hough")


def pose_transform(x: float, y: float, yaw: float) -> np.ndarray:
    """4 x 4 world_from_robot of a planar pose (x, y, yaw)."""
    c, s = np.cos(yaw), np.sin(yaw)
    t = np.eye(4)
    t[:2, :2] = [[c, -s], [s, c]]
    t[0, 3], t[1, 3] = x, y
    return t


def detection_frame(pose: np.ndarray, robot_from_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Frames for a camera on a robot at planar ``pose`` (x, y, yaw).

    Returns (rotation, world_from_sensor): pass ``rotation`` to :func:`depth_to_cloud`
    (points in a sensor-centred frame with the world's axes, z up) and
    ``world_from_sensor`` to :func:`register_planes` / :meth:`Plane.transformed` to put
    the detected planes in the world frame.
    """
    w_from_c = pose_transform(float(pose[0]), float(pose[1]), float(pose[2])) @ np.asarray(robot_from_camera, dtype=np.float64)
    w_from_s = np.eye(4)
    w_from_s[:3, 3] = w_from_c[:3, 3]
    return w_from_c[:3, :3].copy(), w_from_s


def register_planes(
    tree: PlaneOctree,
    detection: PlaneDetection,
    world_from_sensor: np.ndarray,
    stamp: int = 0,
    source: str = "",
) -> int:
    """Insert a detection's planes (sensor frame) into a world map; returns how many went in.

    ``world_from_sensor`` is the 4 x 4 transform of the frame the planes were detected in
    (see :func:`detection_frame`).
    """
    n = 0
    for p in detection.planes:
        n += int(tree.insert(p.transformed(world_from_sensor), stamp, source))
    return n


__all__ = [
    "METHODS",
    "POLICIES",
    "HoughConfig",
    "Leaf",
    "MapPlane",
    "OctreeConfig",
    "PatchArrays",
    "Plane",
    "PlaneDetection",
    "PlaneOctree",
    "RansacConfig",
    "SparseAccumulator",
    "accumulator_nbytes",
    "angle_between_planes_deg",
    "dense_accumulator_nbytes",
    "depth_to_cloud",
    "detection_frame",
    "fit_plane",
    "hough_planes",
    "hull_2d",
    "plane_basis",
    "plane_hull",
    "plane_spherical",
    "polygon_area",
    "pose_transform",
    "ransac_planes",
    "register_planes",
    "spherical_normal",
    "to_plane_coords",
]
