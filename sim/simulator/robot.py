"""The omnidirectional base: its MJCF parts, its velocity control and its odometry.

The base is a cylinder on three joints (slide x, slide y, hinge yaw) driven by velocity
actuators. Speed limits are the actuators' control ranges; acceleration limits are both
enforced on the commanded velocity (a rate limiter, as a motor controller does) and
physically, by the actuators' force ranges (mass x max acceleration). Contacts with walls,
furniture and people are real MuJoCo contacts, so collisions can be counted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import mujoco
import numpy as np

from autonomy.common.constants import ROBOT_RADIUS_M
from autonomy.common.errors import InputError
from autonomy.common.geometry import compose_pose, relative_pose, wrap_angle
from autonomy.navigation.avoidance import AvoidanceConfig

#: Collision bits. Robot collides with static world and people; static world and people
#: do not test each other (both are kinematic), and nothing tests the floor.
COLL_ROBOT = 1
COLL_STATIC = 2
COLL_PEOPLE = 4

#: Geom group for the robot body: hidden from the depth camera.
ROBOT_GEOM_GROUP = 3


@dataclass(frozen=True)
class RobotConfig:
    """A CoBot-like omnidirectional base."""

    radius_m: float = ROBOT_RADIUS_M
    """Collision radius of the base."""
    height_m: float = 1.0
    """Height of the collision cylinder."""
    mass_kg: float = 40.0
    """Base mass (sets the force limits together with the accelerations)."""
    max_speed_mps: float = 0.75
    """Translational speed limit."""
    max_angular_rad_s: float = 1.5
    """Yaw-rate limit."""
    max_accel_mps2: float = 1.0
    """Translational acceleration limit."""
    max_angular_accel_rad_s2: float = 3.0
    """Yaw acceleration limit."""
    velocity_gain: float = 40.0
    """Velocity servo gain per kg (1/s): time constant 1/gain."""

    def __post_init__(self) -> None:
        for name in (
            "radius_m",
            "height_m",
            "mass_kg",
            "max_speed_mps",
            "max_angular_rad_s",
            "max_accel_mps2",
            "max_angular_accel_rad_s2",
            "velocity_gain",
        ):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"robot.{name}: expected a positive number, got {v!r}")

    @property
    def inertia_z(self) -> float:
        """Yaw inertia of a solid cylinder."""
        return 0.5 * self.mass_kg * self.radius_m**2


@dataclass(frozen=True)
class OdometryConfig:
    """Odometry noise: multiplicative Gaussian on each frame's increments (BV2012, VI-A)."""

    translation_noise: float = 0.2
    """Std of the relative error on each translation increment (0.2 = the paper's 20%)."""
    rotation_noise: float = 0.2
    """Std of the relative error on each rotation increment."""
    rotation_per_translation_rad_per_m: float = 0.0
    """Std of extra heading drift per metre driven (additive, 0 = off)."""

    def __post_init__(self) -> None:
        for name in ("translation_noise", "rotation_noise", "rotation_per_translation_rad_per_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InputError(f"odometry.{name}: expected a number >= 0, got {v!r}")


def avoidance_for_body(avoidance: AvoidanceConfig, robot: RobotConfig, where: str) -> AvoidanceConfig:
    """The robot stack's avoidance with the simulated body's radius: ``robot.radius_m`` is
    the one source. An avoidance radius left at its default takes the body's; one set to
    anything else than the body's is a mistake, reported naming ``where``."""
    r = avoidance.robot_radius_m
    if r == robot.radius_m:
        return avoidance
    if r != ROBOT_RADIUS_M:
        raise InputError(
            f"{where}: avoidance.robot_radius_m ({r!r}) differs from robot.radius_m ({robot.radius_m!r}); "
            "set robot.radius_m only (the stack avoids with the simulated body's radius)"
        )
    return replace(avoidance, robot_radius_m=robot.radius_m)


def add_robot(spec: mujoco.MjSpec, cfg: RobotConfig) -> mujoco.MjsBody:
    """Add the base body ``robot`` with joints ``robot_x``, ``robot_y``, ``robot_yaw``.

    The body frame is the robot frame: origin on the floor under the base centre. The
    start pose is set on the joints after compiling (:meth:`RobotHandle.set_pose`).
    """
    body = spec.worldbody.add_body(name="robot", pos=[0.0, 0.0, 0.0])
    body.mass = cfg.mass_kg
    body.inertia = [cfg.inertia_z, cfg.inertia_z, cfg.inertia_z]
    body.ipos = [0.0, 0.0, cfg.height_m / 2]
    body.explicitinertial = True
    for name, jtype, axis in (
        ("robot_x", mujoco.mjtJoint.mjJNT_SLIDE, [1, 0, 0]),
        ("robot_y", mujoco.mjtJoint.mjJNT_SLIDE, [0, 1, 0]),
        ("robot_yaw", mujoco.mjtJoint.mjJNT_HINGE, [0, 0, 1]),
    ):
        j = body.add_joint(name=name, type=jtype, axis=axis)
        j.armature = 0.01
    # Lifted 1 cm so it never touches the floor plane (which has no collision bits anyway).
    body.add_geom(
        name="robot_base",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[cfg.radius_m, (cfg.height_m - 0.01) / 2, 0.0],
        pos=[0.0, 0.0, 0.01 + (cfg.height_m - 0.01) / 2],
        rgba=[0.2, 0.35, 0.8, 1.0],
        contype=COLL_ROBOT,
        conaffinity=COLL_STATIC | COLL_PEOPLE,
        group=ROBOT_GEOM_GROUP,
        friction=[0.3, 0.005, 0.0001],
    )
    kv_lin = cfg.velocity_gain * cfg.mass_kg
    kv_rot = cfg.velocity_gain * cfg.inertia_z
    for jname, kv, vmax, fmax in (
        ("robot_x", kv_lin, cfg.max_speed_mps, cfg.mass_kg * cfg.max_accel_mps2),
        ("robot_y", kv_lin, cfg.max_speed_mps, cfg.mass_kg * cfg.max_accel_mps2),
        (
            "robot_yaw",
            kv_rot,
            cfg.max_angular_rad_s,
            cfg.inertia_z * cfg.max_angular_accel_rad_s2,
        ),
    ):
        a = spec.add_actuator(name=f"{jname}_vel", target=jname, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        a.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        a.gainprm[0] = kv
        a.biasprm[:3] = [0.0, 0.0, -kv]
        a.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        a.ctrlrange = [-vmax, vmax]
        # Force limit = mass x acceleration limit (1.5x headroom for damping losses).
        a.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        a.forcerange = [-1.5 * fmax, 1.5 * fmax]
    return body


@dataclass
class RobotHandle:
    """Indices of the robot in a compiled model, and its velocity controller state."""

    cfg: RobotConfig
    qpos_adr: np.ndarray  # (3,) x, y, yaw
    qvel_adr: np.ndarray  # (3,)
    actuator_ids: np.ndarray  # (3,)
    geom_id: int
    body_id: int
    cmd_world: np.ndarray  # last rate-limited command (vx_w, vy_w, w)

    @classmethod
    def from_model(cls, model: mujoco.MjModel, cfg: RobotConfig) -> RobotHandle:
        jids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in ("robot_x", "robot_y", "robot_yaw")]
        aids = [
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{n}_vel")
            for n in ("robot_x", "robot_y", "robot_yaw")
        ]
        return cls(
            cfg=cfg,
            qpos_adr=np.array([model.jnt_qposadr[j] for j in jids]),
            qvel_adr=np.array([model.jnt_dofadr[j] for j in jids]),
            actuator_ids=np.array(aids),
            geom_id=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "robot_base"),
            body_id=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "robot"),
            cmd_world=np.zeros(3),
        )

    def pose(self, data: mujoco.MjData) -> np.ndarray:
        """Ground-truth pose (x, y, yaw) with yaw wrapped to (-pi, pi]."""
        p = data.qpos[self.qpos_adr].copy()
        p[2] = wrap_angle(p[2])
        return p

    def set_pose(self, data: mujoco.MjData, pose: tuple[float, float, float]) -> None:
        """Teleport the robot (and stop it)."""
        data.qpos[self.qpos_adr] = pose
        data.qvel[self.qvel_adr] = 0.0
        self.cmd_world[:] = 0.0
        data.ctrl[self.actuator_ids] = 0.0

    def velocity_body(self, data: mujoco.MjData) -> np.ndarray:
        """Current body-frame velocity (vx, vy, w)."""
        yaw = data.qpos[self.qpos_adr[2]]
        vw = data.qvel[self.qvel_adr]
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([c * vw[0] + s * vw[1], -s * vw[0] + c * vw[1], vw[2]])

    def command(self, data: mujoco.MjData, v_body: np.ndarray, dt: float) -> None:
        """Set the body-frame velocity command (vx, vy, w), speed- and rate-limited.

        Translational speed is limited on the norm (an omnidirectional base), and the
        change of the world-frame command over ``dt`` by the acceleration limits.
        """
        cfg = self.cfg
        vx, vy, w = (float(v) for v in v_body)
        if not all(math.isfinite(v) for v in (vx, vy, w)):
            raise InputError(f"robot command must be finite, got {v_body!r}")
        speed = math.hypot(vx, vy)
        if speed > cfg.max_speed_mps:
            vx, vy = vx * cfg.max_speed_mps / speed, vy * cfg.max_speed_mps / speed
        w = max(-cfg.max_angular_rad_s, min(cfg.max_angular_rad_s, w))
        yaw = data.qpos[self.qpos_adr[2]]
        c, s = math.cos(yaw), math.sin(yaw)
        target = np.array([c * vx - s * vy, s * vx + c * vy, w])
        dv = target[:2] - self.cmd_world[:2]
        dv_max = cfg.max_accel_mps2 * dt
        n = math.hypot(dv[0], dv[1])
        if n > dv_max:
            dv *= dv_max / n
        self.cmd_world[:2] += dv
        dw_max = cfg.max_angular_accel_rad_s2 * dt
        self.cmd_world[2] += max(-dw_max, min(dw_max, target[2] - self.cmd_world[2]))
        data.ctrl[self.actuator_ids] = self.cmd_world


class Odometry:
    """Wheel odometry: true frame-to-frame increments with multiplicative Gaussian noise.

    Each call to :meth:`update` returns the robot-frame increment (dx, dy, dtheta) since
    the previous call, every component scaled by ``1 + N(0, sigma)`` (translation noise
    on dx and dy, rotation noise on dtheta), plus optional heading drift per metre.
    The integrated (dead-reckoned) pose is kept in :attr:`pose`.
    """

    def __init__(self, cfg: OdometryConfig, rng: np.random.Generator, start_pose: np.ndarray) -> None:
        self.cfg = cfg
        self.rng = rng
        self._last_true = np.asarray(start_pose, dtype=np.float64).copy()
        self.pose = self._last_true.copy()

    def reset(self, true_pose: np.ndarray) -> None:
        """Restart from a pose (dead reckoning restarts there)."""
        self._last_true = np.asarray(true_pose, dtype=np.float64).copy()
        self.pose = self._last_true.copy()

    def rebase(self, true_pose: np.ndarray) -> None:
        """The robot was moved without its wheels turning (carried, bumped): the next
        increment starts from ``true_pose``; the dead-reckoned pose is kept."""
        self._last_true = np.asarray(true_pose, dtype=np.float64).copy()

    def update(self, true_pose: np.ndarray) -> np.ndarray:
        """Noisy increment since the last call."""
        inc = relative_pose(self._last_true, true_pose)
        self._last_true = np.asarray(true_pose, dtype=np.float64).copy()
        cfg = self.cfg
        n = self.rng.standard_normal(4)
        noisy = np.array(
            [
                inc[0] * (1.0 + cfg.translation_noise * n[0]),
                inc[1] * (1.0 + cfg.translation_noise * n[1]),
                inc[2] * (1.0 + cfg.rotation_noise * n[2])
                + cfg.rotation_per_translation_rad_per_m * math.hypot(inc[0], inc[1]) * n[3],
            ]
        )
        self.pose = compose_pose(self.pose, noisy)
        return noisy
