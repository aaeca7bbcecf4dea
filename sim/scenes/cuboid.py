"""Experiment I rig: a cuboid on the floor seen by a camera held by an arm (PlaneMap, III-A).

The paper's Kinect sat on the flange of a KUKA arm and looked down at the cuboid; the
four views of Table I differ in the base axis A1 and the flange axis A6 (A2 = 90,
A3 = -90, A4 = 0, A5 = -50 degrees). Our arm is a kinematic stand-in with those axes:

- A1 turns the whole arm about the vertical axis through its base (the origin);
- the wrist is ``reach_m`` from that axis and ``wrist_height_m`` above the floor;
- A5 pitches the tool axis below the horizontal (A5 = -50: 50 degrees down);
- A6 turns the flange about the tool axis; the Kinect looks along the tool axis, so A6
  rolls the image about the optical axis.

The cuboid stands where the view-1 optical axis meets its mid-height, yawed by
``cuboid_yaw_deg`` from the line of sight so two of its side faces face the camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

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
class ArmView:
    """Joint angles of one view (Table I), degrees."""

    a1_deg: float = 1.59
    """Base axis A1."""
    a5_deg: float = -50.0
    """Wrist pitch A5 (negative = tool axis below the horizontal)."""
    a6_deg: float = 0.0
    """Flange axis A6 (roll about the optical axis)."""


#: PlaneMap Table I (A2 = 90, A3 = -90, A4 = 0 in every view).
TABLE_I_VIEWS = (
    ArmView(1.59, -50.0, 0.0),
    ArmView(1.59, -50.0, 20.0),
    ArmView(1.59, -50.0, -20.0),
    ArmView(5.59, -50.0, 0.0),
)


@dataclass(frozen=True)
class CuboidScene:
    """Geometry of the Experiment I rig (values ours; the paper gives none)."""

    cuboid_size_m: tuple[float, float, float] = (0.5, 0.4, 0.4)
    """Edges of the reference cuboid (x, y, z before its yaw)."""
    cuboid_yaw_deg: float = 40.0
    """Yaw of the cuboid relative to the view-1 line of sight."""
    reach_m: float = 0.9
    """Horizontal distance of the wrist (camera) from the arm's base axis."""
    wrist_height_m: float = 1.3
    """Height of the camera above the floor."""
    reference_view: ArmView = field(default_factory=ArmView)
    """The view whose optical axis meets the cuboid's centre."""

    def __post_init__(self) -> None:
        if len(self.cuboid_size_m) != 3 or not all(v > 0 for v in self.cuboid_size_m):
            raise InputError(f"scene.cuboid_size_m: expected three positive numbers, got {self.cuboid_size_m!r}")
        require_positive(self, "scene.", "reach_m", "wrist_height_m")
        if not self.reference_view.a5_deg < 0:
            raise InputError("scene.reference_view.a5_deg: the camera must look down (a5_deg < 0)")
        if self.wrist_height_m <= self.cuboid_size_m[2] / 2:
            raise InputError("scene.wrist_height_m: the camera must be above the cuboid's mid-height")


def arm_camera_pose(view: ArmView, scene: CuboidScene) -> np.ndarray:
    """4 x 4 world_from_optical of the camera in a view."""
    a1 = math.radians(view.a1_deg)
    a5 = math.radians(view.a5_deg)
    heading = np.array([math.cos(a1), math.sin(a1), 0.0])
    forward = math.cos(a5) * heading + math.sin(a5) * np.array([0.0, 0.0, 1.0])
    t = np.eye(4)
    t[:3, :3] = look_rotation(forward, math.radians(view.a6_deg))
    t[:3, 3] = scene.reach_m * heading + np.array([0.0, 0.0, scene.wrist_height_m])
    return t


def cuboid_pose(scene: CuboidScene) -> tuple[np.ndarray, float]:
    """World centre (3,) and yaw (rad) of the cuboid."""
    cam = arm_camera_pose(scene.reference_view, scene)
    z = cam[:3, 2]
    half_h = scene.cuboid_size_m[2] / 2
    s = (half_h - cam[2, 3]) / z[2]  # along the optical axis down to mid-height
    centre = cam[:3, 3] + s * z
    los = math.atan2(z[1], z[0])
    return centre, los + math.radians(scene.cuboid_yaw_deg)


def cuboid_faces(scene: CuboidScene) -> list[tuple[np.ndarray, float]]:
    """Outward unit normal and offset (n . p = d, world frame) of the cuboid's four side faces."""
    centre, yaw = cuboid_pose(scene)
    c, s = math.cos(yaw), math.sin(yaw)
    ex, ey = np.array([c, s, 0.0]), np.array([-s, c, 0.0])
    hx, hy = scene.cuboid_size_m[0] / 2, scene.cuboid_size_m[1] / 2
    out = []
    for n, h in ((ex, hx), (-ex, hx), (ey, hy), (-ey, hy)):
        out.append((n, float(n @ centre + h)))
    return out


def visible_side_faces(scene: CuboidScene, view: ArmView) -> list[tuple[np.ndarray, float]]:
    """The two side faces the camera sees best (outward normals facing it), most frontal first."""
    cam = arm_camera_pose(view, scene)[:3, 3]
    centre, _ = cuboid_pose(scene)
    to_cam = cam - centre
    to_cam[2] = 0.0
    to_cam /= np.linalg.norm(to_cam)
    faces = sorted(cuboid_faces(scene), key=lambda f: -float(f[0] @ to_cam))
    return faces[:2]


def build_cuboid_rig(scene: CuboidScene, view: ArmView, intr: CameraIntrinsics = CameraIntrinsics()) -> Rig:
    """Floor, cuboid and the arm's camera in one view."""
    spec = new_spec("cuboid_rig", intr)
    spec.worldbody.add_light(name="sun", pos=[0, 0, 10], dir=[0, 0, -1], castshadow=False)
    add_floor(spec)
    centre, yaw = cuboid_pose(scene)
    add_box(spec, "cuboid", centre, [v / 2 for v in scene.cuboid_size_m], yaw)
    cam = arm_camera_pose(view, scene)
    add_camera(spec, cam, intr)
    return compile_rig(spec, cam, intr)
