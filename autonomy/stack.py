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

from autonomy.common.errors import InputError, require_non_negative, require_positive
from autonomy.common.geometry import (
    compose_pose,
    points_from_frame,
    points_in_frame,
    polyline_clear,
    relative_pose,
    sensor_view,
    wrap_angle,
    wrap_angles,
)
from autonomy.localization.active_localization import ActiveLocalizationConfig, drive_value
from autonomy.localization.cgr import CGRConfig, CGRLocalizer, UpdateStats
from autonomy.localization.health import HealthConfig, HealthMonitor, HealthSample, explain_points
from autonomy.localization.missing_walls import MissingWallsConfig, missing_walls
from autonomy.localization.observation import ObservationConfig, correspond
from autonomy.localization.relocalization import GlobalLocalizer, Mode, RelocalizationConfig, Scan
from autonomy.localization.straight_runs import on_straight_runs
from autonomy.localization.view_check import ViewCheck, ViewCheckConfig
from autonomy.maps.freespace import FreeSpaceConfig, build_free_space
from autonomy.maps.planner import NoPathError
from autonomy.maps.raycast import SceneQuery, VisibilityGridConfig, load_or_build
from autonomy.maps.vectormap import NavGraph, VectorMap
from autonomy.navigation.avoidance import AvoidanceConfig, obstacle_points, open_path_lengths
from autonomy.navigation.config import NavCommand, NavigatorConfig
from autonomy.navigation.navigator import Navigator
from autonomy.perception.camera import DepthCamera, frame_checks
from autonomy.perception.floor_rays import floor_rays
from autonomy.perception.fspf import FSPFConfig, FSPFResult, fspf
from autonomy.perception.mount_check import MountCheck, MountCheckConfig
from autonomy.perception.nearfield import NearField, line_points_indexed

#: The visibility grid the stack localizes with: 0.5 m cells, scene lines to 6 m (the
#: Kinect sees 4 m; the margin keeps lines a refined particle may reach).
LOCALIZATION_GRID = VisibilityGridConfig(cell_m=0.5, max_range_m=6.0)
#: Seeds of the FSPF sampling stream stay below this (the kernel's xorshift seed range).
FSPF_SEED_MODULUS = 2**31
#: Stale frames are told by comparing every this-many-th pixel with the last frame's.
STALE_SAMPLE_STRIDE = 7
#: ... while the odometry says the robot moved more than this since those pixels first
#: came (a still scene may repeat; a stuck driver's old frame stays old when it stops).
STALE_MOTION_M = 1e-3
STALE_MOTION_RAD = 1e-3
#: While relocalizing the modes are re-scored each search, and the whole map searched
#: again every this many searches (the scan has grown; a mode dropped early may win).
#: A mode is only accepted on a search of the whole map: one that passes the decision
#: when re-scored brings the next whole-map search forward.
FULL_SEARCH_EVERY = 5
#: While relocalizing, what the robot saw this long ago or less stands in for the map's
#: walls where the camera cannot look: the scan's points, and what the near field shows
#: (something closer than the camera's minimum range), in the dead-reckoning frame. About
#: one look round, so a drive that sets out after it knows what stands beside the robot.
#: Older points are not: dead reckoning a degree or two off over a few metres' drive puts
#: what the robot saw before 0.1-0.2 m from where it is, and a 0.9 m door seen half a
#: minute and two drives ago looks 0.6 m wide to a robot standing in it.
SEEN_KEEP_S = 15.0
#: An exploring plan may pass this much closer to a scan point than the robot's radius
#: (the Kinect's noise on walls beside the path).
EXPLORE_CLEAR_SLACK_M = 0.05
#: While relocalizing, the scan's points on walls are counted again at most this often
#: (a few milliseconds for thousands of points; the scan grows by a frame at a time).
WALL_COUNT_EVERY_S = 0.5
#: A drive to find walls picks among this many ways round the robot ...
PROBE_BEARINGS = 36
#: ... one whose open path is within this of the longest.
PROBE_TIE_M = 0.25


def most_open_way(points: np.ndarray, radius_m: float, reach_m: float) -> float:
    """The bearing (robot frame, rad) of the longest open path (Eq. 3-4) for a robot of
    ``radius_m`` among ``points`` (n, 2), every ``360 / PROBE_BEARINGS`` degrees up to
    ``reach_m``; of the ways within ``PROBE_TIE_M`` of the longest, the one nearest ahead."""
    ang = np.linspace(-math.pi, math.pi, PROBE_BEARINGS, endpoint=False)
    free = open_path_lengths(np.asarray(points, dtype=np.float64).reshape(-1, 2), ang, radius_m, reach_m)
    ways = np.flatnonzero(free >= free.max() - PROBE_TIE_M)
    return float(ang[ways[np.argmin(np.abs(ang[ways]))]])


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
class RecoveryConfig:
    """Lost detection and global relocalization (ours; the papers' operator re-localized
    the robot by hand): :mod:`autonomy.localization.health`, :mod:`autonomy.localization.relocalization`."""

    enabled: bool = True
    """Watch the localization's health and relocalize globally when lost."""
    health: HealthConfig = field(default_factory=HealthConfig)
    """The lost and blind tests."""
    relocalization: RelocalizationConfig = field(default_factory=RelocalizationConfig)
    """Scan, search and decision."""
    check_mount: bool = True
    """Watch the floor for a tilted camera mount and correct the mount FSPF uses
    (:mod:`autonomy.perception.mount_check`)."""
    mount_check: MountCheckConfig = field(default_factory=MountCheckConfig)
    """The mount self-check's parameters."""
    view: ViewCheckConfig = field(default_factory=ViewCheckConfig)
    """The check of each view against the odometry (:mod:`autonomy.localization.view_check`), which
    tells the health monitor that the robot was carried."""
    missing: MissingWallsConfig = field(default_factory=MissingWallsConfig)
    """Which pixels expect a mapped wall, for the health monitor's missing-wall test
    (:mod:`autonomy.localization.missing_walls`)."""
    restart_std_xy_m: float = 0.15
    """CGR restarts around an accepted mode with this position spread ..."""
    restart_std_theta_rad: float = math.radians(4.0)
    """... and this heading spread."""
    explore_check_m: float = 3.0
    """An exploring drive's plan must be clear of the scan's points for this far (robot
    radius less a little Kinect noise)."""
    settle_s: float = 2.0
    """After a relocalization the robot turns in place this long before it drives on,
    while CGR, restarted around the mode, converges: the map's walls in the camera's
    blind spots are placed through the pose, and an accepted mode can be 0.2 m off."""
    explore_after_s: float = 12.0
    """Still undecided after looking this long, the robot drives on the best mode's
    belief to a place ``explore_m`` away (the modes agree on what is near, so the way
    there is the same in all of them), looking as it goes, until the scan decides."""
    explore_m: float = 6.0
    """How far the exploring drive goes before the robot looks round again ..."""
    explore_timeout_s: float = 20.0
    """... or how long it may take (a drive that is blocked looks round again and then
    tries another place)."""
    active: ActiveLocalizationConfig = field(default_factory=ActiveLocalizationConfig)
    """Which exploring drive tells the modes apart (:mod:`autonomy.localization.active_localization`)."""

    def __post_init__(self) -> None:
        require_non_negative(self, "recovery.", "restart_std_xy_m", "restart_std_theta_rad", "settle_s")
        require_positive(self, "recovery.", "explore_after_s", "explore_m", "explore_timeout_s", "explore_check_m")


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
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)
    """Lost detection and global relocalization (needs localization)."""


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
        self.mount = cam.mount
        """The camera mount FSPF and the near field use (the mount check corrects it)."""
        self.mount_check = MountCheck(cam.mount, cfg.recovery.mount_check) if (cfg.recovery.enabled and cfg.recovery.check_mount) else None
        # Recovery: health, dead reckoning, the relocalization's scan and modes.
        rec = cfg.recovery
        self.health: HealthMonitor | None = HealthMonitor(rec.health) if (rec.enabled and self.localizer is not None) else None
        self.view_check: ViewCheck | None = None
        if self.health is not None and rec.view.enabled:
            self.view_check = ViewCheck(rec.view, cam.intrinsics, cam.mount.robot_from_camera(), cam.min_range_m, cam.max_range_m)
        self._depth: np.ndarray | None = None
        self._view_agree = math.nan
        self._missing = (0, 0, 0)
        """The last checked frame's pixels expecting a mapped wall, those of them that
        returned a depth, and those that saw past the wall (:mod:`autonomy.localization.missing_walls`)."""
        self._global: GlobalLocalizer | None = None
        self.odom = np.zeros(3)
        """Dead reckoning from the odometry alone (the relocalization's scan frame)."""
        self.relocalizing = False
        """True while the stack is lost and searching the map (the navigator looks round)."""
        # The camera's rays start ahead of the robot's centre: from the centre, a ray
        # through a door close by its jamb crosses the wall.
        self._sensor_xy = (cam.mount.forward_m, cam.mount.lateral_m)
        rl = rec.relocalization
        self.scan = Scan(rl.scan_cell_m, rl.max_scan_points, self._sensor_xy, rl.floor_cell_m)
        self.modes: list[tuple[np.ndarray, float]] = []
        """Relocalization modes as (map-from-odometry transform, score), best first."""
        self.events: list[dict] = []
        """What the recovery did: {"t", "event": lost | relocalized | blind | seeing, ...}."""
        self.frame_fault = ""
        """What was wrong with this frame ('' nothing): dropped or stale (not used), invalid
        (no valid pixel; used), corrupt (NaN or infinite pixels; used without them)."""
        self.frames_rejected = {"dropped": 0, "stale": 0, "invalid": 0, "corrupt": 0}
        self._prior: np.ndarray | None = None
        self._prior_trusted = True
        self._reloc_t0 = 0.0
        self._settle_until = -math.inf
        self._last_search_t = -math.inf
        self._searches = 0
        self._search_whole_map = False
        self._confirmed = 0
        self._candidate: np.ndarray | None = None
        self._exploring_from: np.ndarray | None = None
        self._explore_T = np.zeros(3)
        self._explore_t0 = 0.0
        self._explored: set[int] = set()
        self._probe: tuple[np.ndarray, float, float] | None = None
        self._walls: tuple[float, int, int] | None = None
        self._near_seen = np.zeros((0, 7))
        self._goal: int | None = None
        self._home: np.ndarray | None = None
        """Where the robot was started (x, y; :meth:`reset`), or the first goal when the
        start was unknown: a goal with no path from there is the user's mistake."""
        self._last_depth_key: np.ndarray | None = None
        self._maybe_stale = False
        self._new_pixels = False
        self._pixels_odom: np.ndarray | None = None
        """The odometry when the last frame's pixels first came (the stale test's origin)."""
        self._fresh = False
        self._t = 0.0
        self._cgr_lines: np.ndarray | None = None
        self._cgr_stats: UpdateStats | None = None
        self.last_search = None
        self._correction: tuple[float, float] | None = None

    # -- belief ------------------------------------------------------------------------
    def reset(self, pose: np.ndarray | None) -> None:
        """Start at a known pose (the mission's start): belief and dead reckoning there.
        ``None``: the pose is unknown; the robot looks round and relocalizes on the map
        first (needs localization with recovery)."""
        self.frame = 0
        self.perception = None
        self.events = []
        self._last_depth_key = None
        self._pixels_odom = None
        self.odom = np.zeros(3) if pose is None else np.asarray(pose, dtype=np.float64).copy()
        self._home = None if pose is None else self.odom[:2].copy()
        if pose is None:
            if self.health is None:
                raise InputError("robot stack: an unknown start pose needs localization with recovery enabled")
            self.pose = np.zeros(3)
            self.spread = (math.inf, math.inf)
            self._start_relocalizing(0.0, prior=None, why="start with an unknown pose")
            return
        self.relocalize(pose)

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
        self._end_relocalizing()
        self._settle_until = -math.inf
        if self.health is not None:
            self.health.reset(self._t)

    def _read_estimate(self) -> None:
        assert self.localizer is not None
        est = self.localizer.estimate()
        self.pose = est.pose.copy()
        self.spread = (est.std_xy_m, est.std_theta_rad)

    # -- the three steps of a frame ----------------------------------------------------
    def perceive(self, depth: np.ndarray | None, seed: int | None = None) -> Perception:
        """FSPF (BV2012 Algorithm 1) on a depth frame (float32 m, 0 = invalid), its
        floor projection (IV-B), the obstacles P u O (Section V) and the near field.
        ``seed`` overrides this frame's FSPF seed (``fspf_seed + frame``).

        ``None`` is a dropped frame; NaN or infinite pixels count as invalid. A dropped
        frame, or the same pixels as the last one while the wheels turn (a stuck driver
        repeating itself, :meth:`localize` tells), is not used: the last perception
        stands and ``frame_fault`` says why. A frame with no valid pixel is used (the
        near field reads it as blocked right ahead) and counted as ``invalid``."""
        cam, cfg = self.cfg.camera, self.cfg
        s = (self.fspf_seed + self.frame) % FSPF_SEED_MODULUS if seed is None else int(seed)
        self.frame += 1
        self.frame_fault = ""
        self._maybe_stale = False
        self._new_pixels = False
        self._fresh = False
        if depth is None:
            return self._reject("dropped")
        depth = np.asarray(depth)
        finite = np.isfinite(depth)
        if not finite.all():
            # A broken driver: its non-finite pixels count as invalid, the rest is used.
            depth = np.where(finite, depth, np.float32(0.0)).astype(np.float32, copy=False)
            self.frame_fault = "corrupt"
            self.frames_rejected["corrupt"] += 1
        valid, repeats = frame_checks(depth, STALE_SAMPLE_STRIDE, self._last_depth_key)
        if not valid:
            # Nothing valid: a camera that fails, or something closer than its minimum
            # range filling the view; the two look alike, and the near field reads both
            # as "blocked right ahead" (it never drives into either). Counted, and used.
            self.frame_fault = "invalid"
            self.frames_rejected["invalid"] += 1
        self._maybe_stale = valid and repeats
        self._new_pixels = valid and not repeats
        self._last_depth_key = depth.ravel()[::STALE_SAMPLE_STRIDE].copy() if valid else None
        t0 = time.perf_counter()
        planes = fspf(depth, cam.intrinsics, cfg.fspf, seed=s, mount=self.mount)
        if self.mount_check is not None:
            corrected = self.mount_check.update(planes)
            if corrected is not None:
                self._correct_mount(corrected)
                planes = fspf(depth, cam.intrinsics, cfg.fspf, seed=s, mount=self.mount)
        p2d, n2d = planes.projected(cfg.fspf.max_vertical_normal_angle_rad)
        t1 = time.perf_counter()
        if self.navigator is not None:
            obstacles = obstacle_points(planes.points, cfg.avoidance, also=planes.outliers)
            assert self.near_field is not None
            near = self.near_field.sight_lines(depth)
        else:
            obstacles, near = np.zeros((0, 2)), np.zeros((0, 4))
        t2 = time.perf_counter()
        self.timings_s = {"fspf": t1 - t0, "obstacles": t2 - t1}
        self.perception = Perception(planes, p2d, n2d, obstacles, near)
        self._fresh = True
        self._depth = depth
        return self.perception

    def _correct_mount(self, mount) -> None:
        """Use a corrected camera mount from now on (FSPF, the near field)."""
        assert self.mount_check is not None
        self.events.append(
            {"t": round(self._t, 3), "event": "mount corrected", "tilt_error_deg": round(float(self.mount_check.tilt_error_deg), 2),
             "pitch_down_deg": round(math.degrees(float(mount.pitch_down_rad)), 2),
             "roll_deg": round(math.degrees(float(getattr(mount, "roll_rad", 0.0))), 2)}
        )
        self.mount = mount
        if self.view_check is not None:
            self.view_check.set_mount(mount.robot_from_camera())
        if self.near_field is not None:
            cam = self.cfg.camera
            try:
                # A camera tilted up may no longer see the configured band of near floor:
                # the nearest floor it sees takes its place (the robot is blind a little
                # farther out, and the event says how far).
                self.near_field = NearField(
                    cam.intrinsics, mount, cam.min_range_m, self.cfg.avoidance.robot_radius_m, self.cfg.avoidance.near_field, shift_band=True
                )
                self.events[-1]["near_floor_m"] = [round(v, 2) for v in self.near_field.band_m]
            except InputError:
                # No floor in view at all: the last near field stays (it watches the
                # pixels the floor was last seen in).
                self.events[-1]["near_floor_m"] = None

    def _reject(self, why: str) -> Perception:
        self.frame_fault = why
        self.frames_rejected[why] += 1
        self.timings_s = {"fspf": 0.0, "obstacles": 0.0}
        if self.perception is None:
            z2, z3 = np.zeros((0, 2)), np.zeros((0, 3))
            self.perception = Perception(FSPFResult(z3, z3, z3, np.zeros(0, np.int64)), z2, z2, z2, np.zeros((0, 4)))
        return self.perception

    def localize(self, increment: np.ndarray | None, t: float | None = None) -> np.ndarray:
        """CGR's predict (odometry ``increment``, robot frame dx, dy, dtheta) and update
        on the last perception's points (BV2012 IV-C); without localization, dead
        reckoning. ``increment`` None: no motion since the last frame (the first one).

        ``t`` (seconds) drives the recovery: the health monitor's averages, the lost test
        and, while lost, the relocalization (:mod:`autonomy.localization.health`,
        :mod:`autonomy.localization.relocalization`). Without it the recovery waits."""
        t0 = time.perf_counter()
        if t is not None:
            self._t = float(t)
        moved = False
        self._cgr_lines = None
        self._cgr_stats = None
        self._correction = None
        self._view_agree = math.nan
        if increment is not None:
            inc = np.asarray(increment, dtype=np.float64)
            if inc.shape != (3,):
                raise InputError(f"robot stack: odometry increment expected (dx, dy, dtheta), got shape {inc.shape}")
            if np.all(np.isfinite(inc)):
                self.odom = compose_pose(self.odom, inc)
                moved = math.hypot(inc[0], inc[1]) > STALE_MOTION_M or abs(inc[2]) > STALE_MOTION_RAD
            if self._maybe_stale and self._pixels_odom is not None:
                # Measured from where these pixels first came, not from the last frame: a
                # robot that stopped (blind for the refused frames) would otherwise take a
                # stuck driver's old view for its own and pull its belief back to it.
                since = relative_pose(self._pixels_odom, self.odom)
                moved = math.hypot(since[0], since[1]) > STALE_MOTION_M or abs(since[2]) > STALE_MOTION_RAD
            if self._maybe_stale and moved:
                # The wheels turned but the camera gave the same pixels: a stale frame.
                self._fresh = False
                self.frame_fault = "stale"
                self.frames_rejected["stale"] += 1
            if self.localizer is None:
                if np.all(np.isfinite(inc)):
                    self.pose = compose_pose(self.pose, inc)
            elif self.relocalizing:
                # Until a mode is accepted the belief is the one before the alarm, dead
                # reckoned (a false alarm leaves it right); without one (an unknown
                # start), the best mode so far.
                if self._prior is not None:
                    self.pose = compose_pose(self._prior, self.odom)
                elif self.modes:
                    self.pose = compose_pose(self.modes[0][0], self.odom)
            else:
                predicted = compose_pose(self.pose, inc)
                self.localizer.predict(inc)
                if self.perception is not None and self._fresh:
                    self._cgr_stats = self.localizer.update(self.perception.points_2d, self.perception.normals_2d)
                    self._cgr_lines = self.localizer.last_lines
                self._read_estimate()
                # How far the update moved the belief beyond the odometry (the jump test).
                self._correction = (float(self.pose[0] - predicted[0]), float(self.pose[1] - predicted[1]))
        if self._new_pixels:
            self._pixels_odom = self.odom.copy()
            self._new_pixels = False
        if t is not None and self.view_check is not None and self._fresh and self._depth is not None:
            if self.relocalizing:  # the health monitor does not listen while relocalizing
                self.view_check.store(float(t), self.odom, self._depth)
            else:
                self._view_agree = self.view_check.update(float(t), self.odom, self._depth)
        if t is not None and self.health is not None:
            if self.relocalizing:
                self._relocalize_step(float(t))
            else:
                self._watch(float(t))
        self.timings_s["localization"] = time.perf_counter() - t0
        return self.pose

    # -- recovery ------------------------------------------------------------------------
    @property
    def health_state(self) -> str:
        """ok, blind, lost (the moment it is noticed) or relocalizing; ok without recovery."""
        if self.relocalizing:
            return "relocalizing"
        return "ok" if self.health is None else self.health.state

    @property
    def correction(self) -> tuple[float, float] | None:
        """How far this frame's localizer update moved the belief beyond the odometry's
        prediction (world x, y; None: no update this frame)."""
        return self._correction

    @property
    def cgr_stats(self) -> UpdateStats | None:
        """What CGR's update did on this frame (None: no update, the frame was refused or
        the robot is relocalizing)."""
        return self._cgr_stats

    @property
    def health_sample(self) -> HealthSample | None:
        """The health monitor's last sample (None without recovery)."""
        return None if self.health is None else self.health.last

    def _watch(self, t: float) -> None:
        """The health monitor on this frame; lost: start relocalizing."""
        assert self.health is not None and self.scene is not None
        per, hc = self.perception, self.cfg.recovery.health
        verdicts = None
        missing = math.nan
        if self._fresh and per is not None:
            # The lines CGR's update just used (seen from its proposal mean, centimetres
            # from the estimate) serve the check too; a second query costs 0.15 ms.
            lines = self._cgr_lines
            if lines is None:
                lines = np.ascontiguousarray(self.scene.scene_lines(float(self.pose[0]), float(self.pose[1]))[0])
            at, rel = sensor_view(self.pose, per.points_2d, self._sensor_xy)
            verdicts = explain_points(lines, at, rel, hc.explain_m, hc.through_m)
            if self._depth is not None and hc.lost_missing > 0.0:
                cam, mc = self.cfg.camera, self.cfg.recovery.missing
                self._missing = missing_walls(
                    self._depth, lines, self.pose, cam.intrinsics, self.mount.robot_from_camera(), cam.min_range_m, cam.max_range_m, mc
                )
                if self._missing[1] >= mc.min_returned:
                    missing = self._missing[2] / self._missing[1]
        was = self.health.state
        sample = self.health.update(t, verdicts, self.spread[0], self._correction, self._view_agree, missing)
        if sample.state != was and "blind" in (sample.state, was) and sample.state != "lost":
            self.events.append({"t": round(t, 3), "event": sample.state if sample.state == "blind" else "seeing"})
        if sample.state == "lost":
            prior = compose_pose(self.pose, relative_pose(self.odom, np.zeros(3)))
            self._start_relocalizing(t, prior, sample.reason)
            # A belief that just jumped is the suspect: it competes with the other places
            # but wins only by the usual margins (a corridor the map repeats fits both).
            self._prior_trusted = sample.reason != "belief jumped"

    def prepare_recovery(self) -> None:
        """Build the relocalization's map search now (the free-space grid, the coarse
        hypotheses and the segment index) and load its kernels
        (:meth:`GlobalLocalizer.warm`, and the count of the scan's wall points) rather
        than at the first alarm: a long run's memory is then steady from its start, and
        the first search does not wait for it."""
        if self.health is not None and self._global is None:
            self.global_localizer().warm()
            on_straight_runs(np.zeros((2, 2)), 1.0)

    def global_localizer(self) -> GlobalLocalizer:
        """The relocalization's map search on this stack's map (built on first use)."""
        if self._global is None:
            r = self.cfg.avoidance.robot_radius_m
            fs = build_free_space(self.vectormap, FreeSpaceConfig(robot_radius_m=r))
            self._global = GlobalLocalizer(
                fs, r, self.cfg.recovery.relocalization, segments=self.vectormap.segments, sensor_xy=self._sensor_xy
            )
        return self._global

    def _start_relocalizing(self, t: float, prior: np.ndarray | None, why: str) -> None:
        self.relocalizing = True
        self._settle_until = -math.inf
        self.scan.clear()
        self.modes = []
        self._prior = prior
        self._prior_trusted = True
        self._reloc_t0 = t
        self._last_search_t = -math.inf
        self._searches = 0
        self._search_whole_map = False
        self._exploring_from = None
        self._explore_t0 = t
        self._explored: set[int] = set()
        self._probe = None
        self._walls = None
        self._near_seen = np.zeros((0, 7))
        self._confirmed = 0
        self._candidate: np.ndarray | None = None
        if self.health is not None:
            # Its averages restart when the robot knows where it is again; a blind state
            # from before would keep the robot from turning to look.
            self.health.reset(t)
        if self.navigator is not None:
            self._goal = self.navigator.goal if self.navigator.goal is not None else self._goal
        self.events.append({"t": round(t, 3), "event": "lost", "why": why, "estimate": [round(float(v), 3) for v in self.pose]})

    def _end_relocalizing(self) -> None:
        self.relocalizing = False
        self.modes = []
        self._prior = None
        self._exploring_from = None
        self._probe = None

    def _relocalize_step(self, t: float) -> None:
        """While lost: grow the scan; once the robot has looked round, search the map (then
        re-score the modes, and search again every few tries, as the scan grows)."""
        rc = self.cfg.recovery.relocalization
        per = self.perception
        if self._fresh and per is not None:
            floor = None
            if rc.floor_weight > 0.0 and self._depth is not None:
                cam = self.cfg.camera
                floor = floor_rays(self._depth, cam.intrinsics, self.mount.robot_from_camera(), rc.floor_stride_px)
            self.scan.add(self.odom, per.points_2d, t, floor)
            self._keep_near(per.near_lines, t)
        looked = self._swept() or self.scan.travelled_m >= rc.min_travel_m
        if not looked or t - self._last_search_t < rc.search_every_s or len(self.scan.points) < rc.min_scan_points:
            return
        self._last_search_t = t
        gl = self.global_localizer()
        assert self.scene is not None
        query = self.scene
        pts = self.scan.in_robot_frame(self.odom)
        origins = self.scan.origins_in_robot_frame(self.odom)
        floor = self.scan.floor_in_robot_frame(self.odom)
        frame_pts = per.points_2d if (self._fresh and per is not None) else None
        prior = None if self._prior is None else compose_pose(self._prior, self.odom)
        full = not self.modes or self._searches % FULL_SEARCH_EVERY == 0 or self._search_whole_map
        self._search_whole_map = False
        times = self.scan.times
        if full:
            res = gl.search(pts, frame_pts, lambda x, y: query.scene_lines(x, y)[0], prior, origins, times, floor)
        else:
            poses = [compose_pose(T, self.odom) for T, _ in self.modes]
            if prior is not None:
                poses.append(prior)
            res = gl.rescore(np.array(poses), pts, frame_pts, lambda x, y: query.scene_lines(x, y)[0], origins, times, floor)
        self._searches += 1
        inv = relative_pose(self.odom, np.zeros(3))
        self.modes = [(compose_pose(m.pose, inv), m.score) for m in res.modes]
        if self.modes and self._prior is None:
            self.pose = compose_pose(self.modes[0][0], self.odom)
        self.last_search = res
        prior_mode = None
        if prior is not None and res.modes and self._prior_trusted:
            # A false alarm ends where it began: the belief before the alarm, if it still
            # explains the scan about as well as the best mode.
            kept = gl.rescore(prior[None, :], pts, origins=origins, times=times, floor=floor).modes
            if kept and gl.keeps_prior(kept[0], res.modes, len(pts)):
                self._accept(kept[0], t, f"the belief before the alarm explains the scan (score {kept[0].score:.3f})", len(res.modes))
                return
            prior_mode = kept[0] if kept else None
        acc = res.accepted
        if acc is not None and not gl.lead_allowed(acc, prior_mode):
            acc = None
        if acc is None:
            self._confirmed = 0
            return
        # Modes compared as map-from-odometry transforms: the robot turns between searches.
        cand = compose_pose(acc.pose, inv)
        same = self._candidate is not None and math.hypot(*(cand[:2] - self._candidate[:2])) < rc.mode_separation_m and abs(
            wrap_angle(float(cand[2] - self._candidate[2]))
        ) < math.radians(rc.mode_separation_deg)
        self._confirmed = self._confirmed + 1 if same else 1
        self._candidate = cand
        if self._confirmed >= rc.confirmations:
            if full:
                self._accept(acc, t, res.reason, len(res.modes))
            else:
                # Re-scoring sees only the modes kept so far; the place the robot is at
                # may not be among them (a room's corner fits hundreds of places).
                self._search_whole_map = True

    def _keep_near(self, near_lines: np.ndarray | None, t: float) -> None:
        """Keep this frame's near-field points (dead-reckoning frame, each with the ends of
        its sight line and its time) for ``SEEN_KEEP_S``. Looking round in place, the
        robot sees nothing closer than 0.8 m; a pillar beside it hides the floor only
        while the camera faces it, and the drive that sets out afterwards would turn into
        it."""
        kept = self._near_seen
        kept = kept[kept[:, 6] >= t - SEEN_KEEP_S]
        lines = np.zeros((0, 4)) if near_lines is None else np.asarray(near_lines, dtype=np.float64).reshape(-1, 4)
        if len(lines):
            pts, line = line_points_indexed(lines, self.cfg.avoidance.near_field.point_step_m)
            ends = points_from_frame(self.odom, lines.reshape(-1, 2)).reshape(-1, 4)
            w = np.column_stack([points_from_frame(self.odom, pts), ends[line], np.full(len(pts), t)])
            kept = np.vstack([w, kept])  # newest first: np.unique keeps the first of a cell
            key = np.floor(kept[:, :2] / self.scan.cell_m).astype(np.int64)
            _, first = np.unique(key[:, 0] * 1_000_003 + key[:, 1], return_index=True)
            kept = kept[np.sort(first)]
        self._near_seen = kept

    def _seen_now(self, t: float, pose: np.ndarray | None = None) -> np.ndarray:
        """What the robot has seen in the last ``SEEN_KEEP_S`` while relocalizing,
        relative to it now: the scan's points, and the near field's. With the ``pose`` of
        the mode a drive is planned on, the near field's points whose sight line a wall
        of that mode's map explains are left out, as the navigator leaves out this
        frame's (:meth:`autonomy.navigation.surroundings.Surroundings.near_points`): the
        map's wall counts there already, where it stands, whereas the sight line's points
        lie anywhere from the robot's edge to the camera's minimum range, and kept from a
        look round beside a wall they ring the robot (a robot put down in an office by
        its door could not turn to the door)."""
        pts = self.scan.recent_in_robot_frame(self.odom, t - SEEN_KEEP_S)
        kept = self._near_seen
        if not len(kept):
            return pts
        near = points_in_frame(self.odom, kept[:, :2])
        if pose is not None and self.navigator is not None:
            ends = points_in_frame(self.odom, kept[:, 2:6].reshape(-1, 2)).reshape(-1, 4)
            lines, inverse = np.unique(ends, axis=0, return_inverse=True)
            explained = self.navigator.walls_explain(pose, lines, with_seen=False)
            near = near[~explained[inverse.reshape(-1)]]
        return np.vstack([pts, near])

    def _accept(self, mode: Mode, t: float, reason: str, n_modes: int) -> None:
        """Restart CGR on the accepted mode; the navigator re-plans to its goal from there."""
        rec = self.cfg.recovery
        assert self.localizer is not None and self.health is not None
        pose = np.asarray(mode.pose, dtype=np.float64).copy()
        self.localizer.reset(pose, rec.restart_std_xy_m, rec.restart_std_theta_rad)
        self.pose = pose
        est = self.localizer.estimate()
        self.spread = (est.std_xy_m, est.std_theta_rad)
        self.events.append(
            {
                "t": round(t, 3), "event": "relocalized", "pose": [round(float(v), 3) for v in pose], "reason": reason,
                "modes": n_modes, "searches": self._searches, "scan_points": len(self.scan.points),
                "looked_s": round(t - self._reloc_t0, 3),
            }
        )
        self._end_relocalizing()
        self.health.reset(t)
        self._settle_until = t + rec.settle_s
        if self.navigator is not None:
            self.navigator.pose_jumped()
            if self._goal is not None:
                self.navigator.set_goal(self._goal, pose, t)

    # -- deciding ------------------------------------------------------------------------
    def decide(self, t: float, pose: np.ndarray | None = None) -> NavCommand:
        """The navigator's command at time ``t`` from the last perception, on the estimate
        (or on ``pose``: a simulation's ground-truth follower). Blind (no usable frame
        for a while), the robot stands still; relocalizing, it turns in place to look
        (and, undecided after ``recovery.explore_after_s``, drives on the best mode), and
        goes on turning for ``recovery.settle_s`` after a mode is accepted."""
        if self.navigator is None:
            raise InputError("robot stack: built with navigate = false, it has no navigator")
        per = self.perception
        obstacles = np.zeros((0, 2)) if per is None else per.obstacles
        near = None if per is None else per.near_lines
        t0 = time.perf_counter()
        if self.health is not None and self.health.state == "blind":
            cmd = NavCommand(np.zeros(3), "blind")
        elif self.relocalizing and pose is None:
            cmd = self._search_motion(t, obstacles, near)
        elif pose is None and t < self._settle_until:
            cmd = self.navigator.look_around(t)
            cmd.state = "settling"
        else:
            cmd = self.navigator.command(self.pose if pose is None else pose, obstacles, t, near)
        self.timings_s["navigation"] = time.perf_counter() - t0
        return cmd

    def _search_motion(self, t: float, obstacles: np.ndarray, near: np.ndarray | None) -> NavCommand:
        """Turn in place to look; looked round with too little wall in the scan, drive to
        find walls (:meth:`_probe_motion`); still undecided after ``explore_after_s``,
        drive ``explore_m`` on the best mode's belief, then look again."""
        rec = self.cfg.recovery
        nav = self.navigator
        assert nav is not None
        if self._probe is not None or (self._swept() and self._lacks_walls(t)):
            cmd = self._probe_motion(t, obstacles, near)
            if cmd is not None:
                return cmd
        if not self.modes or t - self._reloc_t0 < rec.explore_after_s:
            return nav.look_around(t)
        if self._exploring_from is None:
            best = compose_pose(self.modes[0][0], self.odom)
            node = self._explore_node(best, t)
            if node is None:
                return nav.look_around(t)
            nav.pose_jumped()
            nav.set_goal(node, best, t)
            self._exploring_from = self.odom.copy()
            self._explore_T = self.modes[0][0].copy()
            self._explore_t0 = t
            self._explored.add(node)
        # One drive sees the world through the transform of the mode it set out on: the
        # modes are re-scored every second and the best may change, but a plan, the
        # obstacle memory and the map's walls in the camera's blind spots placed through
        # one mode and then read through another would put walls where none are seen.
        best = compose_pose(self._explore_T, self.odom)
        if self._ruled_out(best):
            # The scan has ruled out the mode this drive set out on: its plan leads
            # nowhere the robot is. Set out at once on the best mode now (the scan
            # already holds the surroundings; no new look round is needed).
            self._exploring_from = None
            return self._search_motion(t, obstacles, near)
        # The scan's walls count with the map's where the camera cannot look: the map is
        # placed through a mode that may be wrong (a door beside the robot that the
        # mode's map has elsewhere).
        cmd = nav.command(best, obstacles, t, near, seen=self._seen_now(t, best))
        gone = math.hypot(*(self.odom[:2] - self._exploring_from[:2]))
        if cmd.state == "arrived" or gone >= rec.explore_m or t - self._explore_t0 > rec.explore_timeout_s:
            # Look round again from here (the scan keeps what it saw on the way).
            self._exploring_from = None
            self._reloc_t0 = t
            self.scan.turned_rad = 0.0
            return nav.look_around(t)
        cmd.state = "exploring" if cmd.state in ("driving", "turning") else cmd.state
        return cmd

    def _lacks_walls(self, t: float) -> bool:
        """Whether the scan is too small to search (``min_scan_points``) or holds too
        little wall (``min_wall_points`` of its points on straight runs at least
        ``min_wall_m`` long, :func:`autonomy.localization.straight_runs.on_straight_runs`; counted at
        most every ``WALL_COUNT_EVERY_S`` while it grows)."""
        rc = self.cfg.recovery.relocalization
        n = len(self.scan.points)
        if n < rc.min_scan_points:
            return True
        if rc.min_wall_points == 0:
            return False
        if self._walls is None or t - self._walls[0] >= WALL_COUNT_EVERY_S or n < self._walls[1]:
            self._walls = (t, n, int(on_straight_runs(self.scan.points, rc.min_wall_m).sum()))
        return self._walls[2] < rc.min_wall_points

    def _swept(self) -> bool:
        """Whether the robot has looked round since it last set out (``min_sweep_deg``)."""
        return self.scan.turned_rad >= math.radians(self.cfg.recovery.relocalization.min_sweep_deg)

    def _probe_motion(self, t: float, obstacles: np.ndarray, near: np.ndarray | None) -> NavCommand | None:
        """Looked round without seeing enough wall to search the map by (:meth:`_lacks_walls`:
        in a hall whose walls all lie beyond the camera's 4 m the scan holds a pillar or
        two, or pillars and furniture the map lacks, which fit no place clearly), drive to
        find walls: on dead reckoning alone, the way the scan shows most open (Eq. 3's
        open path length on what the robot has seen, :meth:`_seen_now`, every
        ``360 / PROBE_BEARINGS`` degrees up to ``explore_m``; of the ways as open as the
        most, the one nearest ahead): the walls lie beyond the camera's range that way,
        and a way towards what the scan holds can end at a chair. It avoids what the
        camera sees, until the scan holds enough wall, ``explore_m`` is behind or
        ``explore_timeout_s`` has passed; then it looks round again (None: the caller
        does). The searches go on meanwhile, and one that decides ends the drive. The next
        probe sets out from where this one ended, the way most open from there."""
        rec = self.cfg.recovery
        nav = self.navigator
        assert nav is not None
        if self._probe is None:
            rel = most_open_way(self._seen_now(t), self.cfg.avoidance.robot_radius_m, rec.explore_m)
            self._probe = (self.odom.copy(), wrap_angle(float(self.odom[2]) + rel), t)
            # The memory and trail were placed through the belief before the alarm; this
            # drive sees the world in the odometry's frame.
            nav.pose_jumped()
        start, heading, t0 = self._probe
        gone = math.hypot(float(self.odom[0] - start[0]), float(self.odom[1] - start[1]))
        if not self._lacks_walls(t) or gone >= rec.explore_m or t - t0 > rec.explore_timeout_s:
            self._probe = None
            self._reloc_t0 = t
            self.scan.turned_rad = 0.0
            nav.pose_jumped()
            return None
        cmd = nav.head_for(self.odom, heading, obstacles, t, near, seen=self._seen_now(t))
        cmd.state = "exploring" if cmd.state in ("driving", "turning") else cmd.state
        return cmd

    def _ruled_out(self, pose: np.ndarray) -> bool:
        """Whether no mode near ``pose`` (within the modes' separation) scores within
        ``recovery.active.abandon_margin`` of the best mode."""
        if not self.modes:
            return False
        rc = self.cfg.recovery.relocalization
        limit = self.modes[0][1] + self.cfg.recovery.active.abandon_margin
        sep = math.radians(rc.mode_separation_deg)
        for T, score in self.modes:
            if score > limit:
                break
            p = compose_pose(T, self.odom)
            if math.hypot(p[0] - pose[0], p[1] - pose[1]) < rc.mode_separation_m and abs(wrap_angle(float(p[2] - pose[2]))) < sep:
                return False
        return True

    def _explore_node(self, pose: np.ndarray, t: float) -> int | None:
        """A navigation-graph node ``explore_m`` to twice that from the pose, among those
        not tried yet in this relocalization, whose plan's first ``explore_check_m`` the
        scan's points of the last ``SEEN_KEEP_S`` show clear: the one whose drive tells the most modes apart
        (:func:`autonomy.localization.active_localization.drive_value`), the one most nearly ahead (the
        robot goes on the way it faces) among equals.

        The plan is made on the best mode's map, and only to nodes it can set out to from
        the pose there (:meth:`Navigator.reaches`): a mode in a part of the graph cut off
        from the others (a wrong mode in a room the map has no door to) has none of
        those, and the robot looks round again (None) rather than set out through a wall.
        Where the modes disagree about the way out of a room (offices that mirror each
        other), a wrong mode's plan can lead into a wall the robot has already seen; the
        scan rules such plans out, and when it rules out all of them the one most nearly
        ahead is tried."""
        nav = self.navigator
        assert nav is not None
        rec = self.cfg.recovery
        xy = nav.graph.node_xy()
        d = np.hypot(xy[:, 0] - pose[0], xy[:, 1] - pose[1])
        m = rec.explore_m
        cand = np.flatnonzero((d >= m) & (d <= 2 * m))
        ids = np.array([nav.graph.nodes[int(k)].id for k in cand], dtype=np.int64)
        if len(cand):
            keep = nav.reaches(ids, pose)
            cand, ids = cand[keep], ids[keep]
        fresh = ~np.isin(ids, np.array(sorted(self._explored), dtype=np.int64))
        if fresh.any():  # a place not tried yet (the last one may have been blocked)
            cand = cand[fresh]
        if not len(cand):
            return None
        bearing = np.abs(wrap_angles(np.arctan2(xy[cand, 1] - pose[1], xy[cand, 0] - pose[0]) - pose[2]))
        order = cand[np.argsort(bearing, kind="stable")]
        seen = self.scan.recent_in_robot_frame(self.odom, t - SEEN_KEEP_S)
        modes = self._compared_modes(pose)
        best, best_value = None, -1.0
        for k in order:
            node = int(nav.graph.nodes[int(k)].id)
            path = nav.plan_points(node, pose)
            if not polyline_clear(points_in_frame(pose, path), seen, rec.explore_check_m, self.cfg.avoidance.robot_radius_m - EXPLORE_CLEAR_SLACK_M):
                continue
            if len(modes) < 2:
                return node
            value = self._drive_value(path, modes)
            if value > best_value + 1e-9:
                best, best_value = node, value
        if best is not None:
            return best
        return int(nav.graph.nodes[int(order[0])].id)

    def _compared_modes(self, pose: np.ndarray) -> np.ndarray:
        """The modes an exploring drive should tell apart (M, 3), ``pose`` (the best
        mode's, which the drive is planned on) first; fewer than two: none to compare."""
        act = self.cfg.recovery.active
        if not act.enabled or not self.modes:
            return np.zeros((0, 3))
        top = self.modes[0][1]
        others = [compose_pose(T, self.odom) for T, s in self.modes[1 : act.modes] if s <= top + act.score_margin]
        return np.array([pose, *others]).reshape(-1, 3)

    def _drive_value(self, path: np.ndarray, modes: np.ndarray) -> float:
        """What a drive along ``path`` is worth to tell ``modes`` apart."""
        assert self.scene is not None
        query = self.scene
        cam = self.cfg.camera
        return drive_value(
            lambda x, y: query.scene_lines(x, y)[0], path, modes, self.cfg.recovery.active,
            self.cfg.recovery.explore_m, cam.fov_h_rad, cam.max_range_m,
        )

    def step(
        self, depth: np.ndarray | None, increment: np.ndarray | None, t: float, pose: np.ndarray | None = None
    ) -> StackOutput:
        """One frame: perceive, localize, and (when navigating) decide."""
        per = self.perceive(depth)
        self.localize(increment, t)
        cmd = self.decide(t, pose) if self.navigator is not None else None
        return StackOutput(cmd, self.pose.copy(), self.spread, per, dict(self.timings_s))

    # -- goals ---------------------------------------------------------------------------
    def set_goal(self, node_id: int, t: float, pose: np.ndarray | None = None) -> float:
        """Plan to a navigation-graph node from the estimate (or ``pose``); returns the
        plan's length in metres. While relocalizing the goal is kept for when the robot
        knows where it is again (the length is then the best mode's).

        A goal that the place the robot was started at (:meth:`reset`; unknown there,
        the first goal) has no path to is the user's mistake:
        :class:`autonomy.maps.planner.NoPathError`. One that only the belief has no path to
        (a wrong belief in a part of the graph cut off from the goal) is the robot's:
        the plan starts at the nearest node that reaches the goal, and the localization
        recovers the belief (:meth:`Navigator.set_goal`)."""
        nav = self.navigator
        if nav is None:
            raise InputError("robot stack: built with navigate = false, it has no navigator")
        if self._home is None:
            home = nav.graph.node_xy()[nav.graph.index_of(int(node_id))]
            self._home = np.asarray(home, dtype=np.float64).copy()
        elif not nav.reaches(int(node_id), self._home)[0]:
            start = nav.nearest_reachable_node(self._home)
            raise NoPathError(f"no path from node {start} (where the robot started) to node {int(node_id)} in the navigation graph")
        self._goal = int(node_id)
        at = self.pose if pose is None else pose
        if self.relocalizing and pose is None:
            return self.navigator.plan_length(int(node_id), at)
        return self.navigator.set_goal(node_id, at, t)

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
