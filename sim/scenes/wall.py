"""Experiment II rig: the camera facing a flat wall at a measured distance (PlaneMap, III-B).

The paper's Kinect stood on a table, its front 106 cm and then 156 cm from a flat wall.
Here the optical centre is ``distance_m`` from the wall, ``camera_height_m`` above the
floor, looking straight at it (optical axis along the wall normal, level). The wall is
wide and tall enough to fill the whole image; the floor is out of view at these
distances.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from autonomy.common.errors import InputError, require_positive
from autonomy.perception.camera import CameraIntrinsics
from sim.scenes.rigs import (
    Rig,
    add_box,
    add_camera,
    add_floor,
    compile_rig,
    look_rotation,
    new_spec,
)


@dataclass(frozen=True)
class WallScene:
    """Geometry of the Experiment II rig."""

    camera_height_m: float = 0.8
    """Height of the optical centre (a camera on a table)."""
    wall_width_m: float = 8.0
    """Wall width (fills the field of view)."""
    wall_height_m: float = 3.0
    """Wall height."""
    wall_thickness_m: float = 0.1
    """Wall thickness (behind its front face)."""

    def __post_init__(self) -> None:
        require_positive(self, "scene.", "camera_height_m", "wall_width_m", "wall_height_m", "wall_thickness_m")


def wall_camera_pose(distance_m: float, scene: WallScene) -> np.ndarray:
    """4 x 4 world_from_optical: camera at (0, 0, h) looking along +x at the wall x = distance."""
    t = np.eye(4)
    t[:3, :3] = look_rotation(np.array([1.0, 0.0, 0.0]))
    t[:3, 3] = [0.0, 0.0, scene.camera_height_m]
    return t


def build_wall_rig(distance_m: float, scene: WallScene = WallScene(), intr: CameraIntrinsics = CameraIntrinsics()) -> Rig:
    """The wall (front face at x = distance_m, normal -x) and the camera facing it."""
    if not distance_m > 0:
        raise InputError(f"wall distance: expected a positive number, got {distance_m!r}")
    spec = new_spec("wall_rig", intr)
    spec.worldbody.add_light(name="sun", pos=[0, 0, 10], dir=[0, 0, -1], castshadow=False)
    add_floor(spec)
    t = scene.wall_thickness_m
    add_box(spec, "wall", [distance_m + t / 2, 0.0, scene.wall_height_m / 2], [t / 2, scene.wall_width_m / 2, scene.wall_height_m / 2])
    cam = wall_camera_pose(distance_m, scene)
    add_camera(spec, cam, intr)
    return compile_rig(spec, cam, intr)
