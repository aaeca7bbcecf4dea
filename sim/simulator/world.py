"""Blueprint (vector map) -> MuJoCo world, built with the ``mujoco.MjSpec`` API.

Every map segment becomes two boxes centred on the map line: a 2 cm collision box
``wall_<i>`` that the robot meets (thick enough that no physics step passes through it)
and that the camera does not draw, and a 1 mm face box ``wall_face_<i>`` that the camera
sees and nothing collides with. So the surface the depth camera measures lies on the
blueprint's line (0.5 mm off), as a map built from laser scans puts its lines on the
surfaces it saw. A 1 cm offset between the seen face and the map line is no small
error for localization: between two walls nearly parallel (1 degree apart, common on
drawn floor plans) it moves the best fit along the corridor by about 0.6 m. A thick
physical wall is two lines in a blueprint, as in real CoBot maps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from autonomy.common.errors import InputError
from autonomy.maps.vectormap import VectorMap
from autonomy.perception.camera import CameraIntrinsics, CameraMount
from sim.simulator.actors import (
    FURNITURE_PREFIX,
    PERSON_PREFIX,
    Furniture,
    PeopleController,
    Person,
    add_furniture,
    add_people,
)
from sim.simulator.robot import (
    COLL_ROBOT,
    COLL_STATIC,
    ROBOT_GEOM_GROUP,
    RobotConfig,
    RobotHandle,
    add_robot,
)

#: The geom group the depth camera does not draw (the robot's own body is in it too).
CAMERA_HIDDEN_GROUP = ROBOT_GEOM_GROUP

#: Camera name of the Kinect in every world.
KINECT_CAMERA = "kinect"

#: MuJoCo cameras look down -z with y up; the optical frame looks down +z with y down.
MJCAM_FROM_OPTICAL = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class WorldConfig:
    """How a blueprint becomes a MuJoCo world."""

    wall_height_m: float = 2.5
    """Height of every wall."""
    wall_thickness_m: float = 0.02
    """Thickness of the wall's collision box (the camera does not see it)."""
    wall_face_thickness_m: float = 0.001
    """Thickness of the wall box the camera sees: its faces lie half of it off the map
    line."""
    ceiling: bool = False
    """Add a ceiling slab at wall height."""
    floor_margin_m: float = 5.0
    """Floor extends this far beyond the map's extent."""
    timestep_s: float = 1.0 / 240.0
    """Physics time step."""

    def __post_init__(self) -> None:
        for name in ("wall_height_m", "wall_thickness_m", "wall_face_thickness_m", "timestep_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise InputError(f"world.{name}: expected a positive number, got {v!r}")
        if self.floor_margin_m < 0:
            raise InputError(f"world.floor_margin_m: expected a number >= 0, got {self.floor_margin_m!r}")


def _wall_boxes(segments: np.ndarray, thickness: float, height: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres (N, 3), half sizes (N, 3) and wxyz quaternions (N, 4) of the wall boxes."""
    p0, p1 = segments[:, :2], segments[:, 2:]
    d = p1 - p0
    length = np.hypot(d[:, 0], d[:, 1])
    yaw = np.arctan2(d[:, 1], d[:, 0])
    n = len(segments)
    centres = np.empty((n, 3))
    centres[:, :2] = 0.5 * (p0 + p1)
    centres[:, 2] = height / 2
    half = np.empty((n, 3))
    half[:, 0] = length / 2
    half[:, 1] = thickness / 2
    half[:, 2] = height / 2
    quats = np.zeros((n, 4))
    quats[:, 0] = np.cos(yaw / 2)
    quats[:, 3] = np.sin(yaw / 2)
    return centres, half, quats


def optical_quat(rot_from_optical: np.ndarray) -> np.ndarray:
    """wxyz quaternion of the MuJoCo camera whose optical frame has this rotation (in its
    parent: the world, or the robot body)."""
    mat = np.asarray(rot_from_optical, dtype=np.float64) @ MJCAM_FROM_OPTICAL
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, mat.reshape(-1))
    return q


def camera_quat(mount: CameraMount) -> np.ndarray:
    """wxyz orientation of the MuJoCo camera in the robot body for a mount."""
    return optical_quat(mount.rotation())


def build_spec(
    vectormap: VectorMap,
    *,
    world: WorldConfig = WorldConfig(),
    robot: RobotConfig = RobotConfig(),
    intrinsics: CameraIntrinsics = CameraIntrinsics(),
    mount: CameraMount = CameraMount(),
    furniture: tuple[Furniture, ...] = (),
    people: tuple[Person, ...] = (),
) -> mujoco.MjSpec:
    """The MjSpec of a building: floor, walls, optional ceiling, furniture, people, robot."""
    spec = mujoco.MjSpec()
    spec.modelname = vectormap.name or "building"
    spec.option.timestep = world.timestep_s
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.gravity = [0.0, 0.0, -9.81]
    set_depth_rendering(spec, intrinsics)
    _add_floor(spec, vectormap, world)
    _add_walls(spec, vectormap, world)
    if world.ceiling:
        _add_ceiling(spec, vectormap, world)
    add_furniture(spec, tuple(furniture))
    add_people(spec, tuple(people))
    body = add_robot(spec, robot)
    body.add_camera(
        name=KINECT_CAMERA,
        pos=mount.translation(),
        quat=camera_quat(mount),
        fovy=math.degrees(intrinsics.fov_v_rad),
    )
    return spec


def set_depth_rendering(spec: mujoco.MjSpec, intrinsics: CameraIntrinsics) -> None:
    """An offscreen buffer the camera fits in, and only what depth needs (every spec a
    Kinect renders, buildings and rigs alike)."""
    vis = spec.visual
    vis.global_.offwidth = max(640, intrinsics.width)
    vis.global_.offheight = max(480, intrinsics.height)
    vis.quality.shadowsize = 0
    # No multisampling: a resolved MSAA depth buffer holds one sub-sample, not the pixel centre.
    vis.quality.offsamples = 0
    # One quad per box face: the default subdivision (for smooth lighting) triples the
    # render time on a CPU rasteriser and changes nothing in depth.
    vis.quality.numquads = 1


def _footprint(vectormap: VectorMap, margin_m: float) -> tuple[float, float, float, float]:
    """Centre (x, y) and half sizes (x, y) of the map's extent grown by ``margin_m``."""
    xmin, ymin, xmax, ymax = vectormap.extent()
    return (xmin + xmax) / 2, (ymin + ymax) / 2, (xmax - xmin) / 2 + margin_m, (ymax - ymin) / 2 + margin_m


def _add_floor(spec: mujoco.MjSpec, vectormap: VectorMap, world: WorldConfig) -> None:
    """A light overhead and the floor plane (which nothing collides with)."""
    cx, cy, hx, hy = _footprint(vectormap, world.floor_margin_m)
    wb = spec.worldbody
    wb.add_light(name="sun", pos=[cx, cy, 30.0], dir=[0, 0, -1], castshadow=False)
    wb.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[hx, hy, 1.0],
        pos=[cx, cy, 0.0],
        rgba=[0.75, 0.75, 0.72, 1.0],
        contype=0,
        conaffinity=0,
    )


def _add_walls(spec: mujoco.MjSpec, vectormap: VectorMap, world: WorldConfig) -> None:
    """Per map segment a collision box ``wall_<i>`` (all of them first, so their ids are
    contiguous) in the group the camera does not draw, then a face box ``wall_face_<i>``
    the camera sees and nothing collides with (module docstring)."""
    segments = np.asarray(vectormap.segments)
    wall_rgba = [0.92, 0.9, 0.85, 1.0]
    for prefix, thickness, bits, group in (
        ("wall", world.wall_thickness_m, (COLL_STATIC, COLL_ROBOT), CAMERA_HIDDEN_GROUP),
        ("wall_face", world.wall_face_thickness_m, (0, 0), 0),
    ):
        centres, half, quats = _wall_boxes(segments, thickness, world.wall_height_m)
        for i in range(len(centres)):
            spec.worldbody.add_geom(
                name=f"{prefix}_{i}",
                type=mujoco.mjtGeom.mjGEOM_BOX,
                size=half[i],
                pos=centres[i],
                quat=quats[i],
                rgba=wall_rgba,
                contype=bits[0],
                conaffinity=bits[1],
                group=group,
            )


def _add_ceiling(spec: mujoco.MjSpec, vectormap: VectorMap, world: WorldConfig) -> None:
    """A 10 cm slab resting on the walls (which nothing collides with)."""
    cx, cy, hx, hy = _footprint(vectormap, world.floor_margin_m)
    spec.worldbody.add_geom(
        name="ceiling",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[hx, hy, 0.05],
        pos=[cx, cy, world.wall_height_m + 0.05],
        rgba=[0.95, 0.95, 0.95, 1.0],
        contype=0,
        conaffinity=0,
    )


@dataclass
class World:
    """A compiled building with handles to what the simulation drives and measures."""

    model: mujoco.MjModel
    data: mujoco.MjData
    vectormap: VectorMap
    config: WorldConfig
    robot: RobotHandle
    people: PeopleController
    camera_id: int
    intrinsics: CameraIntrinsics
    mount: CameraMount
    furniture: tuple[Furniture, ...] = ()
    wall_geom_start: int = 0
    _robot_in_contact: bool = field(default=False, repr=False)
    collision_log: list[dict] = field(default_factory=list, repr=False)
    """One entry per collision event: time, robot x/y, and what was touched."""

    @property
    def n_walls(self) -> int:
        return self.vectormap.n_segments

    def reset(self, pose: tuple[float, float, float], t: float = 0.0) -> None:
        """Put the robot at a pose, people at their t positions, and recompute derived state."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.time = t
        self.robot.set_pose(self.data, pose)
        self.people.reset(np.asarray(pose[:2], dtype=np.float64))
        self.people.update(self.data, t)
        mujoco.mj_forward(self.model, self.data)
        self._robot_in_contact = False
        self.collision_log.clear()

    def robot_contacts(self) -> list[int]:
        """Geom ids currently touching the robot (walls, furniture, people)."""
        g = self.robot.geom_id
        c = self.data.contact
        n = self.data.ncon
        if n == 0:
            return []
        g1, g2 = c.geom1[:n], c.geom2[:n]
        other = np.where(g1 == g, g2, np.where(g2 == g, g1, -1))
        return [int(o) for o in other[other >= 0]]

    def step_frame(self, n_substeps: int) -> int:
        """Advance the physics ``n_substeps`` steps; return new collision events (0 or 1).

        A collision event is the start of a contact episode: the robot touching anything
        after not touching anything in the previous step.
        """
        events = 0
        for _ in range(n_substeps):
            mujoco.mj_step(self.model, self.data)
            touching = self.data.ncon > 0 and bool(self.robot_contacts())
            if touching and not self._robot_in_contact:
                events += 1
                self.collision_log.append(self._describe_contact())
            self._robot_in_contact = touching
        return events

    def contact_kind(self, geom_id: int) -> str:
        """What a geom belongs to: 'wall', 'furniture', 'person' or 'other'."""
        body = mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_BODY, int(self.model.geom_bodyid[geom_id])) or ""
        if body.startswith(PERSON_PREFIX):
            return "person"
        if body.startswith(FURNITURE_PREFIX):
            return "furniture"
        if self.wall_geom_start <= geom_id < self.wall_geom_start + self.n_walls:
            return "wall"
        return "other"

    def _describe_contact(self) -> dict:
        geoms = self.robot_contacts()
        pose = self.robot.pose(self.data)
        v = self.robot.velocity_body(self.data)
        # Where on the robot the contact is: bearing of the first contact point in the
        # robot frame (0 = straight ahead, +90 = left), to tell blind-zone contacts apart.
        g = self.robot.geom_id
        n = self.data.ncon
        idx = [i for i in range(n) if g in (int(self.data.contact.geom1[i]), int(self.data.contact.geom2[i]))]
        bearing = float("nan")
        if idx:
            p = self.data.contact.pos[idx[0]]
            bearing = math.degrees(math.atan2(p[1] - pose[1], p[0] - pose[0]) - pose[2])
            bearing = (bearing + 180.0) % 360.0 - 180.0
        return {
            "t": round(float(self.data.time), 3),
            "x": round(float(pose[0]), 3),
            "y": round(float(pose[1]), 3),
            "speed_mps": round(float(np.hypot(v[0], v[1])), 3),
            "heading_deg": round(math.degrees(float(pose[2])), 1),
            "bearing_deg": round(bearing, 1),
            "with": sorted({self.contact_kind(g) for g in geoms}),
            "bodies": sorted({mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_BODY, int(self.model.geom_bodyid[g])) or "world" for g in geoms}),
        }

    def geom_name(self, geom_id: int) -> str:
        return mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_GEOM, geom_id) or f"geom_{geom_id}"


def build_world(
    vectormap: VectorMap,
    *,
    world: WorldConfig = WorldConfig(),
    robot: RobotConfig = RobotConfig(),
    intrinsics: CameraIntrinsics = CameraIntrinsics(),
    mount: CameraMount = CameraMount(),
    furniture: tuple[Furniture, ...] = (),
    people: tuple[Person, ...] = (),
    start_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> World:
    """Compile a building world and put the robot at ``start_pose``."""
    spec = build_spec(
        vectormap,
        world=world,
        robot=robot,
        intrinsics=intrinsics,
        mount=mount,
        furniture=furniture,
        people=people,
    )
    return compile_world(
        spec, vectormap, world=world, robot=robot, intrinsics=intrinsics, mount=mount,
        furniture=furniture, people=people, start_pose=start_pose,
    )


def compile_world(
    spec: mujoco.MjSpec,
    vectormap: VectorMap,
    *,
    world: WorldConfig,
    robot: RobotConfig,
    intrinsics: CameraIntrinsics,
    mount: CameraMount,
    furniture: tuple[Furniture, ...] = (),
    people: tuple[Person, ...] = (),
    start_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> World:
    """Compile a spec from :func:`build_spec` (possibly edited, e.g. a camera moved) into a
    :class:`World` with the robot at ``start_pose``."""
    model = spec.compile()
    # The model's extent scales the GL near and far planes. Compiled, it depends on every
    # body, parked actors included; taken from the map alone, a building renders the same
    # depth however many actors its world holds (the env parks spare ones far away).
    xmin, ymin, xmax, ymax = vectormap.extent()
    model.stat.extent = max(1.0, float(np.hypot(xmax - xmin, ymax - ymin)))
    # Depth precision: near plane at 5 cm, far plane at 60 m (model.vis.map is relative to extent).
    model.vis.map.znear = 0.05 / model.stat.extent
    model.vis.map.zfar = 60.0 / model.stat.extent
    data = mujoco.MjData(model)
    w = World(
        model=model,
        data=data,
        vectormap=vectormap,
        config=world,
        robot=RobotHandle.from_model(model, robot),
        people=PeopleController.from_model(model, tuple(people), np.asarray(vectormap.segments), robot.radius_m),
        camera_id=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, KINECT_CAMERA),
        intrinsics=intrinsics,
        mount=mount,
        furniture=tuple(furniture),
        wall_geom_start=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "wall_0") if vectormap.n_segments else -1,
    )
    w.reset(start_pose)
    return w
