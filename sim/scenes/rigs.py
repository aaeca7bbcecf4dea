"""Small MuJoCo rigs with a free-standing depth camera (PlaneMap, Experiments I and II).

A rig is a static scene (floor, boxes) plus a camera fixed in the world at a given
optical-frame pose, compiled with the same visual settings as :mod:`sim.simulator.world` so
:class:`sim.simulator.kinect.KinectCamera` renders it the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from autonomy.perception.camera import CameraIntrinsics
from sim.simulator.kinect import KinectCamera, KinectConfig
from sim.simulator.world import KINECT_CAMERA, optical_quat, set_depth_rendering

#: Name of the rig's depth camera (the name every world gives its Kinect).
RIG_CAMERA = KINECT_CAMERA


@dataclass
class Rig:
    """A compiled rig: model, data, the camera and where it is."""

    model: mujoco.MjModel
    data: mujoco.MjData
    camera_id: int
    world_from_camera: np.ndarray
    """4 x 4 transform world_from_optical of the camera."""
    intrinsics: CameraIntrinsics

    def camera(self, cfg: KinectConfig) -> KinectCamera:
        """A Kinect on the rig's camera (close it when done)."""
        return KinectCamera(self.model, self.camera_id, cfg)


def new_spec(name: str, intr: CameraIntrinsics) -> mujoco.MjSpec:
    """An empty spec with the depth-rendering settings of :func:`sim.simulator.world.build_spec`."""
    spec = mujoco.MjSpec()
    spec.modelname = name
    set_depth_rendering(spec, intr)
    return spec


def add_camera(spec: mujoco.MjSpec, world_from_optical: np.ndarray, intr: CameraIntrinsics) -> None:
    """A fixed world camera named :data:`RIG_CAMERA` at an optical-frame pose."""
    spec.worldbody.add_camera(
        name=RIG_CAMERA,
        pos=world_from_optical[:3, 3],
        quat=optical_quat(world_from_optical[:3, :3]),
        fovy=math.degrees(intr.fov_v_rad),
    )


def add_floor(spec: mujoco.MjSpec, half_m: float = 10.0) -> None:
    """A floor plane at z = 0."""
    spec.worldbody.add_geom(
        name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[half_m, half_m, 1.0], rgba=[0.7, 0.7, 0.68, 1.0]
    )


def add_box(spec: mujoco.MjSpec, name: str, centre, half_sizes, yaw_rad: float = 0.0) -> None:
    """A static box (yawed about z)."""
    spec.worldbody.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(half_sizes),
        pos=list(centre),
        quat=[math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2)],
        rgba=[0.8, 0.6, 0.4, 1.0],
    )


def compile_rig(spec: mujoco.MjSpec, world_from_optical: np.ndarray, intr: CameraIntrinsics) -> Rig:
    """Compile a rig spec (near plane 5 cm, far plane 60 m) and find its camera."""
    model = spec.compile()
    model.vis.map.znear = 0.05 / model.stat.extent
    model.vis.map.zfar = 60.0 / model.stat.extent
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    cid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, RIG_CAMERA)
    return Rig(model, data, cid, np.asarray(world_from_optical, dtype=np.float64).copy(), intr)


def look_rotation(forward: np.ndarray, roll_rad: float = 0.0) -> np.ndarray:
    """world_from_optical rotation of a camera looking along ``forward`` (image x horizontal), rolled."""
    z = np.asarray(forward, dtype=np.float64)
    z = z / np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-9:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(roll_rad), math.sin(roll_rad)
    xr, yr = c * x + s * y, -s * x + c * y
    return np.column_stack([xr, yr, z])
