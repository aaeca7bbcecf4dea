"""Experiment III rig: a rectangular corridor loop and a robot whose camera looks right.

PlaneMap, III-C: the robot drives a corridor loop counter-clockwise, starting at its
lower right, with the Kinect turned -90 degrees about the robot's z axis (looking to the
right side, where the walls are), level, so the floor stays out of view. Corridor parts
in the paper are 10-16 m long.

The blueprint is a closed ring corridor between an outer and an inner rectangle, with
recessed doorways every ``door_spacing_m`` along the outer walls (the side the camera
sees). The world is :func:`sim.simulator.world.build_spec` with the camera turned to the right.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from autonomy.common.errors import InputError, require_positive
from autonomy.maps.vectormap import VectorMap
from autonomy.perception.camera import ROBOT_FROM_OPTICAL_LEVEL, CameraIntrinsics, CameraMount
from sim.simulator.robot import RobotConfig
from sim.simulator.world import (
    KINECT_CAMERA,
    World,
    WorldConfig,
    build_spec,
    compile_world,
    optical_quat,
)


@dataclass(frozen=True)
class CorridorScene:
    """The corridor loop and the camera on the robot (values ours unless noted)."""

    length_m: float = 16.0
    """Outer extent along x (the paper's corridor parts: 10-16 m)."""
    width_m: float = 10.0
    """Outer extent along y."""
    corridor_width_m: float = 2.4
    """Wall-to-wall width of the corridor."""
    door_spacing_m: float = 4.0
    """Distance between recessed doorways along the outer walls (0 = none)."""
    door_width_m: float = 1.0
    """Width of a doorway recess."""
    door_depth_m: float = 0.3
    """Depth of a doorway recess behind the wall line."""
    camera_height_m: float = 0.8
    """Height of the optical centre above the floor."""
    camera_yaw_deg: float = -90.0
    """Camera yaw about the robot's z axis (-90: looking right; the paper)."""

    def __post_init__(self) -> None:
        require_positive(self, "scene.", "length_m", "width_m", "corridor_width_m", "door_width_m", "door_depth_m", "camera_height_m")
        if self.door_spacing_m < 0:
            raise InputError(f"scene.door_spacing_m: expected a number >= 0, got {self.door_spacing_m!r}")
        if min(self.length_m, self.width_m) <= 2 * self.corridor_width_m + 0.5:
            raise InputError("scene: length_m and width_m must exceed twice corridor_width_m by 0.5 m")
        if self.door_spacing_m and self.door_spacing_m <= self.door_width_m:
            raise InputError("scene.door_spacing_m: expected more than door_width_m")


def _wall_with_doors(p0: np.ndarray, p1: np.ndarray, outward: np.ndarray, scene: CorridorScene) -> list[list[float]]:
    """Segments of a wall from p0 to p1 with doorway recesses pushed ``outward``."""
    d = p1 - p0
    length = float(np.hypot(*d))
    e = d / length
    segs: list[list[float]] = []
    if scene.door_spacing_m <= 0:
        return [[*p0, *p1]]
    n_doors = int((length - scene.corridor_width_m) // scene.door_spacing_m)
    margin = (length - (n_doors - 1) * scene.door_spacing_m) / 2 if n_doors else 0.0
    cur = p0
    for k in range(max(n_doors, 0)):
        mid = margin + k * scene.door_spacing_m
        a = p0 + e * (mid - scene.door_width_m / 2)
        b = p0 + e * (mid + scene.door_width_m / 2)
        a2, b2 = a + outward * scene.door_depth_m, b + outward * scene.door_depth_m
        segs += [[*cur, *a], [*a, *a2], [*a2, *b2], [*b2, *b]]
        cur = b
    segs.append([*cur, *p1])
    return segs


def corridor_map(scene: CorridorScene = CorridorScene()) -> VectorMap:
    """The blueprint: outer rectangle (with doorways) and inner rectangle, lower left at the origin."""
    L, W, c = scene.length_m, scene.width_m, scene.corridor_width_m
    o = [np.array(p, dtype=np.float64) for p in ((0, 0), (L, 0), (L, W), (0, W))]
    outward = [np.array(v, dtype=np.float64) for v in ((0, -1), (1, 0), (0, 1), (-1, 0))]
    segs: list[list[float]] = []
    for k in range(4):
        segs += _wall_with_doors(o[k], o[(k + 1) % 4], outward[k], scene)
    i = [(c, c), (L - c, c), (L - c, W - c), (c, W - c)]
    for k in range(4):
        segs.append([*i[k], *i[(k + 1) % 4]])
    return VectorMap.from_segments(np.array(segs, dtype=np.float64), name="corridor_ring")


def corridor_path(scene: CorridorScene = CorridorScene()) -> np.ndarray:
    """The loop's centre line, counter-clockwise from the lower right corner: (5, 2) closed polyline."""
    L, W, h = scene.length_m, scene.width_m, scene.corridor_width_m / 2
    return np.array([(L - h, h), (L - h, W - h), (h, W - h), (h, h), (L - h, h)], dtype=np.float64)


def robot_from_camera(scene: CorridorScene) -> np.ndarray:
    """4 x 4 robot_from_camera (optical frame) of the right-looking, level camera."""
    yaw = math.radians(scene.camera_yaw_deg)
    rz = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    t = np.eye(4)
    t[:3, :3] = rz @ ROBOT_FROM_OPTICAL_LEVEL
    t[:3, 3] = [0.0, 0.0, scene.camera_height_m]
    return t


def build_corridor_world(
    scene: CorridorScene = CorridorScene(),
    *,
    world: WorldConfig = WorldConfig(),
    robot: RobotConfig = RobotConfig(),
    intrinsics: CameraIntrinsics = CameraIntrinsics(),
    start_pose: tuple[float, float, float] | None = None,
) -> World:
    """The corridor world with the robot at the loop's start, its camera turned right.

    The world's ``mount`` is the camera height only; use :func:`robot_from_camera` for
    the camera's full pose on the robot.
    """
    vm = corridor_map(scene)
    mount = CameraMount(height_m=scene.camera_height_m, forward_m=0.0, lateral_m=0.0, pitch_down_rad=0.0)
    spec = build_spec(vm, world=world, robot=robot, intrinsics=intrinsics, mount=mount)
    cam = spec.camera(KINECT_CAMERA)
    t = robot_from_camera(scene)
    cam.pos = t[:3, 3]
    cam.quat = optical_quat(t[:3, :3])
    if start_pose is None:
        p = corridor_path(scene)
        start_pose = (float(p[0, 0]), float(p[0, 1]), math.atan2(p[1, 1] - p[0, 1], p[1, 0] - p[0, 0]))
    return compile_world(spec, vm, world=world, robot=robot, intrinsics=intrinsics, mount=mount, start_pose=start_pose)
