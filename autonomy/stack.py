"""The robot-side stack behind one entry point: depth frame + odometry + time -> command.

:class:`RobotStack` owns every per-frame module of the robot (BV2012): FSPF on the depth
image (Algorithm 1), CGR localization on the plane-filtered points (Section IV), the
obstacle points P u O and the near field, and the navigator with its obstacle memory and
avoidance (Eq. 3-5). It needs no simulator: feed it a real Kinect's frames (float32
metres, 0 = invalid) and wheel-odometry increments and it drives.

One frame is three steps, callable separately where a user needs only some of them:

1. :meth:`RobotStack.perceive` -- FSPF, the floor-plane projection, obstacles, near field;
2. :meth:`RobotStack.localize` -- CGR predict and update (or dead reckoning when
   localization is off);
3. :meth:`RobotStack.decide` -- the navigator's velocity command on the estimate.

:meth:`RobotStack.step` runs all three and returns a :class:`StackOutput` with the command,
the estimate and what a viewer or a report needs (planes, particles, the avoidance fan,
per-stage timings).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from autonomy.avoidance import AvoidanceConfig, obstacle_points
from autonomy.camera import DepthCamera
from autonomy.cgr import CGRConfig, CGRLocalizer
from autonomy.errors import InputError
from autonomy.fspf import FSPFConfig, FSPFResult, fspf
from autonomy.geometry import compose_pose
from autonomy.navigator import NavCommand, Navigator, NavigatorConfig
from autonomy.nearfield import NearField
from autonomy.observation import ObservationConfig, correspond
from autonomy.raycast import SceneQuery, VisibilityGridConfig, load_or_build
from autonomy.vectormap import NavGraph, VectorMap

#: The visibility grid the stack localizes with: 0.5 m cells, scene lines to 6 m (the
#: Kinect sees 4 m; the margin keeps lines a refined particle may reach).
LOCALIZATION_GRID = VisibilityGridConfig(cell_m=0.5, max_range_m=6.0)
#: Seeds of the FSPF sampling stream stay below this (the kernel's xorshift seed range).
FSPF_SEED_MODULUS = 2**31


@dataclass(frozen=True)
class LocalizationConfig:
    """CGR localization on FSPF points (BV2012, Section IV)."""

    enabled: bool = True
    """Run CGR every frame; off: the estimate is dead reckoning from the odometry."""
    cgr: CGRConfig = field(default_factory=CGRConfig)
    """Particle filter parameters."""
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    """Point-cloud observation model parameters (Eq. 1-2)."""
    grid: VisibilityGridConfig = LOCALIZATION_GRID
    """Visibility grid for the analytic ray cast (Algorithm 2)."""


@dataclass(frozen=True)
class StackConfig:
    """Everything the robot-side stack needs besides the map."""

    camera: DepthCamera = field(default_factory=DepthCamera)
    """The depth camera: intrinsics, mount and valid range (one source for all modules)."""
    fspf: FSPFConfig = field(default_factory=FSPFConfig)
    """FSPF parameters (BV2012 Table I)."""
    localization: LocalizationConfig = field(default_factory=LocalizationConfig)
    """CGR localization."""
    avoidance: AvoidanceConfig = field(default_factory=AvoidanceConfig)
    """Obstacle avoidance (Eq. 3-5), the robot radius and the near field."""
    navigator: NavigatorConfig = field(default_factory=NavigatorConfig)
    """Carrot following, speed limits, memory and recovery."""
    navigate: bool = True
    """Run the navigator (off: perception and localization only, as in offline replays)."""


@dataclass
class Perception:
    """What one depth frame told the robot (robot frame)."""

    planes: FSPFResult
    """FSPF's plane-filtered points P with normals R, and outliers O."""
    points_2d: np.ndarray
    """P down-projected to the floor (k, 2), floor-like normals dropped (the observation)."""
    normals_2d: np.ndarray
    """Their unit 2D normals (k, 2)."""
    obstacles: np.ndarray
    """P u O inside the avoidance's height band, down-projected (m, 2)."""
    near_lines: np.ndarray
    """Near-field sight lines (n, 4): something closer than the camera's minimum range."""


@dataclass
class StackOutput:
    """One frame of the stack: the command, the belief, and what viewers and reports read."""

    command: NavCommand | None
    """The navigator's decision (None when the stack does not navigate)."""
    estimate: np.ndarray
    """Pose estimate (x, y, theta) in the map frame."""
    spread: tuple[float, float]
    """(position spread m, heading spread rad) of the belief; (0, 0) for dead reckoning."""
    perception: Perception
    """This frame's FSPF result, observation points, obstacles and near field."""
    timings_s: dict[str, float]
    """Seconds spent in each stage this frame: fspf, obstacles, localization, navigation."""

    @property
    def velocity(self) -> np.ndarray:
        """Body-frame velocity command (vx, vy, omega); zero when not navigating."""
        return np.zeros(3) if self.command is None else self.command.velocity


class RobotStack:
    """FSPF, CGR, near field, obstacle memory and navigator: one object, one step a frame."""

    def __init__(
        self,
        vectormap: VectorMap,
        navgraph: NavGraph | None,
        cfg: StackConfig = StackConfig(),
        *,
        rng: np.random.Generator,
        fspf_seed: int = 0,
        scene: SceneQuery | None = None,
        map_path: str | Path | None = None,
    ) -> None:
        """``rng`` drives CGR's sampling; ``fspf_seed`` starts FSPF's per-frame seeds
        (frame k uses ``fspf_seed + k``). ``scene`` is the map's ray-cast query; without
        it one is made (its visibility grid cached beside ``map_path`` when given)."""
        if cfg.navigate and navgraph is None:
            raise InputError("robot stack: navigating needs a navigation graph")
        self.cfg = cfg
        self.vectormap = vectormap
        self.fspf_seed = int(fspf_seed)
        cam = cfg.camera
        self.scene: SceneQuery | None = None
        self.localizer: CGRLocalizer | None = None
        loc = cfg.localization
        if loc.enabled:
            self.scene = scene if scene is not None else SceneQuery(vectormap, load_or_build(vectormap, map_path, loc.grid))
            query = self.scene
            self.localizer = CGRLocalizer(lambda x, y: query.scene_lines(x, y)[0], loc.cgr, loc.observation, rng)
        self.navigator: Navigator | None = None
        self.near_field: NearField | None = None
        if cfg.navigate:
            walls = np.asarray(vectormap.segments)
            self.navigator = Navigator(navgraph, cfg.navigator, cfg.avoidance, walls=walls, camera=cam)
            self.near_field = NearField(
                cam.intrinsics, cam.mount, cam.min_range_m, cfg.avoidance.robot_radius_m, cfg.avoidance.near_field
            )
        self.frame = 0
        self.pose = np.zeros(3)
        self.spread = (0.0, 0.0)
        self.perception: Perception | None = None
        self.timings_s: dict[str, float] = {}

    # -- belief ------------------------------------------------------------------------
    def reset(self, pose: np.ndarray) -> None:
        """Start at a known pose (the mission's start): belief and dead reckoning there."""
        self.relocalize(pose)
        self.frame = 0
        self.perception = None

    def relocalize(self, pose: np.ndarray) -> None:
        """Re-initialise the belief around ``pose`` (an operator's reset, or a
        simulation's truth reset when the error passes the failure threshold)."""
        # The estimate is the given pose itself until the next update, not the mean of
        # the particles just drawn around it: the pose is known.
        self.pose = np.asarray(pose, dtype=np.float64).copy()
        self.spread = (0.0, 0.0)
        if self.localizer is not None:
            self.localizer.reset(self.pose)
            est = self.localizer.estimate()
            self.spread = (est.std_xy_m, est.std_theta_rad)

    def _read_estimate(self) -> None:
        assert self.localizer is not None
        est = self.localizer.estimate()
        self.pose = est.pose.copy()
        self.spread = (est.std_xy_m, est.std_theta_rad)

    # -- the three steps of a frame ----------------------------------------------------
    def perceive(self, depth: np.ndarray, seed: int | None = None) -> Perception:
        """FSPF (BV2012 Algorithm 1) on a depth frame (float32 m, 0 = invalid), its
        floor projection (IV-B), the obstacles P u O (Section V) and the near field.
        ``seed`` overrides this frame's FSPF seed (``fspf_seed + frame``)."""
        cam, cfg = self.cfg.camera, self.cfg
        s = (self.fspf_seed + self.frame) % FSPF_SEED_MODULUS if seed is None else int(seed)
        t0 = time.perf_counter()
        planes = fspf(depth, cam.intrinsics, cfg.fspf, seed=s, mount=cam.mount)
        p2d, n2d = planes.projected(cfg.fspf.max_vertical_normal_angle_rad)
        t1 = time.perf_counter()
        if self.navigator is not None:
            obstacles = obstacle_points(np.vstack([planes.points, planes.outliers]), cfg.avoidance)
            assert self.near_field is not None
            near = self.near_field.sight_lines(depth)
        else:
            obstacles, near = np.zeros((0, 2)), np.zeros((0, 4))
        t2 = time.perf_counter()
        self.timings_s = {"fspf": t1 - t0, "obstacles": t2 - t1}
        self.perception = Perception(planes, p2d, n2d, obstacles, near)
        self.frame += 1
        return self.perception

    def localize(self, increment: np.ndarray | None) -> np.ndarray:
        """CGR's predict (odometry ``increment``, robot frame dx, dy, dtheta) and update
        on the last perception's points (BV2012 IV-C); without localization, dead
        reckoning. ``increment`` None: no motion since the last frame (the first one)."""
        t0 = time.perf_counter()
        if increment is not None:
            inc = np.asarray(increment, dtype=np.float64)
            if inc.shape != (3,):
                raise InputError(f"robot stack: odometry increment expected (dx, dy, dtheta), got shape {inc.shape}")
            if self.localizer is None:
                if np.all(np.isfinite(inc)):
                    self.pose = compose_pose(self.pose, inc)
            else:
                self.localizer.predict(inc)
                if self.perception is not None:
                    self.localizer.update(self.perception.points_2d, self.perception.normals_2d)
                self._read_estimate()
        self.timings_s["localization"] = time.perf_counter() - t0
        return self.pose

    def decide(self, t: float, pose: np.ndarray | None = None) -> NavCommand:
        """The navigator's command at time ``t`` from the last perception, on the estimate
        (or on ``pose``: a simulation's ground-truth follower)."""
        if self.navigator is None:
            raise InputError("robot stack: built with navigate = false, it has no navigator")
        per = self.perception
        obstacles = np.zeros((0, 2)) if per is None else per.obstacles
        near = None if per is None else per.near_lines
        t0 = time.perf_counter()
        cmd = self.navigator.command(self.pose if pose is None else pose, obstacles, t, near)
        self.timings_s["navigation"] = time.perf_counter() - t0
        return cmd

    def step(
        self, depth: np.ndarray, increment: np.ndarray | None, t: float, pose: np.ndarray | None = None
    ) -> StackOutput:
        """One frame: perceive, localize, and (when navigating) decide."""
        per = self.perceive(depth)
        self.localize(increment)
        cmd = self.decide(t, pose) if self.navigator is not None else None
        return StackOutput(cmd, self.pose.copy(), self.spread, per, dict(self.timings_s))

    # -- goals ---------------------------------------------------------------------------
    def set_goal(self, node_id: int, t: float, pose: np.ndarray | None = None) -> float:
        """Plan to a navigation-graph node from the estimate (or ``pose``); returns the
        plan's length in metres."""
        if self.navigator is None:
            raise InputError("robot stack: built with navigate = false, it has no navigator")
        return self.navigator.set_goal(node_id, self.pose if pose is None else pose, t)

    # -- for viewers ---------------------------------------------------------------------
    def correspondences(self) -> tuple[np.ndarray, np.ndarray]:
        """The scene lines visible from the estimate and, for each observation point, the
        index of the line it is associated with there (-1: none), as CGR's observation
        model associates them (BV2012 Eq. 1). For viewers; costs one association pass."""
        per = self.perception
        if self.scene is None or per is None:
            return np.zeros((0, 4)), np.zeros(0, dtype=np.int64)
        est = self.pose
        lines = np.ascontiguousarray(self.scene.scene_lines(float(est[0]), float(est[1]))[0])
        p2d = np.ascontiguousarray(per.points_2d, dtype=np.float64)
        idx = np.full(len(p2d), -1, dtype=np.int64)
        if len(lines) and len(p2d):
            ocfg = self.cfg.localization.observation
            correspond(
                lines, est, p2d, np.ascontiguousarray(per.normals_2d, dtype=np.float64), True,
                math.cos(ocfg.theta_max_rad), ocfg.max_distance_m, idx,
            )
        return lines, idx
