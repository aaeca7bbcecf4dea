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

:meth:`RobotStack.step` runs all three and returns a :class:`StackOutput`
(:mod:`autonomy.stack.output`): the command for the motion until the next frame, the
belief, the plan, the health and the events, and what a viewer needs. A program that
drives the robot with the stack reads it through these outputs alone; what it tells the
stack are commands (:meth:`~RobotStack.reset`, :meth:`~RobotStack.set_goal` and
:meth:`~RobotStack.redecide` after it, :meth:`~RobotStack.relocalize`,
:meth:`~RobotStack.prepare_recovery`).

Its parts: the frame guard (:mod:`autonomy.stack.frames`), the recovery when lost
(:mod:`autonomy.stack.lost`, :mod:`autonomy.stack.lost_view`,
:mod:`autonomy.stack.search_motion`), sharing the belief and the last frame
(:mod:`autonomy.stack.state`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import compose_pose
from autonomy.localization.cgr import CGRLocalizer
from autonomy.localization.health import HealthMonitor, HealthSample
from autonomy.localization.observation import associate
from autonomy.localization.view_check import ViewCheck
from autonomy.maps.navgraph import NavGraph
from autonomy.maps.planner import NoPathError
from autonomy.maps.raycast import SceneQuery, load_or_build
from autonomy.maps.vectormap import VectorMap
from autonomy.navigation.avoidance import obstacle_points
from autonomy.navigation.config import NavCommand
from autonomy.navigation.navigator import Navigator
from autonomy.perception.camera import CameraMount
from autonomy.perception.fspf import fspf
from autonomy.perception.mount_check import MountCheck
from autonomy.perception.nearfield import NearField
from autonomy.stack.config import StackConfig
from autonomy.stack.frames import FrameGuard, moved_more_than_noise
from autonomy.stack.lost import Accepted, LostRecovery
from autonomy.stack.output import PlanView, Refinement, StackOutput
from autonomy.stack.state import LocalizationFrame, Perception, StackState, empty_perception

#: Seeds of the FSPF sampling stream stay below this (the kernel's xorshift seed range).
FSPF_SEED_MODULUS = 2**31


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
            self.navigator = Navigator(navgraph, cfg.navigator, cfg.avoidance, walls=np.asarray(vectormap.segments), camera=cam)
            self.near_field = NearField(cam.intrinsics, cam.mount, cam.min_range_m, cfg.avoidance.robot_radius_m, cfg.avoidance.near_field)
        self.frame = 0
        self.state = StackState(mount=cam.mount)
        self.timings_s: dict[str, float] = {}
        self.guard = FrameGuard()
        self.mount_check = MountCheck(cam.mount, cfg.recovery.mount_check) if (cfg.recovery.enabled and cfg.recovery.check_mount) else None
        rec = cfg.recovery
        self.health: HealthMonitor | None = HealthMonitor(rec.health) if cfg.recovers else None
        self.view_check: ViewCheck | None = None
        if self.health is not None and rec.view.enabled:
            self.view_check = ViewCheck(rec.view, cam.intrinsics, cam.mount.robot_from_camera(), cam.min_range_m, cam.max_range_m)
        self.lost = LostRecovery(cfg, self.state, vectormap, self.scene, self.health, self.navigator)
        self._home: np.ndarray | None = None
        """Where the robot was started (x, y; :meth:`reset`), or the first goal when the
        start was unknown: a goal with no path from there is the user's mistake."""
        self._loc = LocalizationFrame()
        self._events_out: tuple[dict, ...] = ()
        """The event log as the last output gave it (made again only when it grew)."""

    # -- belief ------------------------------------------------------------------------
    def reset(self, pose: np.ndarray | None) -> StackOutput:
        """Start at a known pose (the mission's start): belief and dead reckoning there.
        ``None``: the pose is unknown; the robot looks round and relocalizes on the map
        first (needs localization with recovery). Returns the output at the start (no
        frame seen, no command)."""
        st = self.state
        self.frame = 0
        st.perception = None
        st.events = []
        self._events_out = ()
        self.guard.reset()
        st.odom = np.zeros(3) if pose is None else np.asarray(pose, dtype=np.float64).copy()
        self._home = None if pose is None else st.odom[:2].copy()
        if pose is None:
            if self.health is None:
                raise InputError("robot stack: an unknown start pose needs localization with recovery enabled")
            st.pose = np.zeros(3)
            st.spread = (math.inf, math.inf)
            self.lost.start(0.0, prior=None, why="start with an unknown pose")
        else:
            self.relocalize(pose)
        return self._output(None, None)

    def relocalize(self, pose: np.ndarray) -> None:
        """Re-initialise the belief around ``pose`` (an operator's reset, or a
        simulation's truth reset when the error passes the failure threshold)."""
        st = self.state
        # The estimate is the given pose itself until the next update, not the mean of
        # the particles just drawn around it: the pose is known.
        st.pose = np.asarray(pose, dtype=np.float64).copy()
        st.spread = (0.0, 0.0)
        if self.localizer is not None:
            self.localizer.reset(st.pose)
            est = self.localizer.estimate()
            st.spread = (est.std_xy_m, est.std_theta_rad)
        self.lost.end()
        self.lost.settle_until = -math.inf
        if self.health is not None:
            self.health.reset(st.t)

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
        cam, cfg, st = self.cfg.camera, self.cfg, self.state
        s = (self.fspf_seed + self.frame) % FSPF_SEED_MODULUS if seed is None else int(seed)
        self.frame += 1
        self.guard.begin()
        st.fresh = False
        if depth is None:
            return self._reject("dropped")
        depth = self.guard.check(np.asarray(depth))
        t0 = time.perf_counter()
        planes = fspf(depth, cam.intrinsics, cfg.fspf, seed=s, mount=st.mount)
        corrected = None if self.mount_check is None else self.mount_check.update(planes)
        if corrected is not None:
            self._correct_mount(corrected)
            planes = fspf(depth, cam.intrinsics, cfg.fspf, seed=s, mount=st.mount)
        p2d, n2d = planes.projected(cfg.fspf.max_vertical_normal_angle_rad)
        t1 = time.perf_counter()
        obstacles, near = np.zeros((0, 2)), np.zeros((0, 4))
        if self.navigator is not None and self.near_field is not None:
            obstacles = obstacle_points(planes.points, cfg.avoidance, also=planes.outliers)
            near = self.near_field.sight_lines(depth)
        t2 = time.perf_counter()
        self.timings_s = {"fspf": t1 - t0, "obstacles": t2 - t1}
        st.perception = Perception(planes, p2d, n2d, obstacles, near)
        st.fresh = True
        st.depth = depth
        return st.perception

    def _correct_mount(self, mount: CameraMount) -> None:
        """Use a corrected camera mount from now on (FSPF, the view check, the near field)."""
        assert self.mount_check is not None
        event = self.mount_check.correction_event(self.state.t, mount)
        self.state.events.append(event)
        self.state.mount = mount
        if self.view_check is not None:
            self.view_check.set_mount(mount.robot_from_camera())
        if self.near_field is not None:
            near = self.near_field.for_mount(mount)
            event["near_floor_m"] = None if near is None else [round(v, 2) for v in near.band_m]
            self.near_field = near or self.near_field

    def _reject(self, why: str) -> Perception:
        self.guard.reject(why)
        self.timings_s = {"fspf": 0.0, "obstacles": 0.0}
        if self.state.perception is None:
            self.state.perception = empty_perception()
        return self.state.perception

    def localize(self, increment: np.ndarray | None, t: float | None = None) -> np.ndarray:
        """CGR's predict (odometry ``increment``, robot frame dx, dy, dtheta) and update
        on the last perception's points (BV2012 IV-C); without localization, dead
        reckoning. ``increment`` None: no motion since the last frame (the first one).

        ``t`` (seconds) drives the recovery: the health monitor's averages, the lost test
        and, while lost, the relocalization (:mod:`autonomy.localization.health`,
        :mod:`autonomy.localization.relocalization`). Without it the recovery waits."""
        t0 = time.perf_counter()
        st = self.state
        if t is not None:
            st.t = float(t)
        self._loc = LocalizationFrame()
        if increment is not None:
            inc = np.asarray(increment, dtype=np.float64)
            if inc.shape != (3,):
                raise InputError(f"robot stack: odometry increment expected (dx, dy, dtheta), got shape {inc.shape}")
            moved = False
            if np.all(np.isfinite(inc)):
                st.odom = compose_pose(st.odom, inc)
                moved = moved_more_than_noise(inc)
            if self.guard.stale(st.odom, moved):
                st.fresh = False
            if self.localizer is None:
                if np.all(np.isfinite(inc)):
                    st.pose = compose_pose(st.pose, inc)
            elif self.lost.relocalizing:
                belief = self.lost.belief(st.odom)
                if belief is not None:
                    st.pose = belief
            else:
                predicted = compose_pose(st.pose, inc)
                self.localizer.predict(inc)
                if st.perception is not None and st.fresh:
                    self._loc.stats = self.localizer.update(st.perception.points_2d, st.perception.normals_2d)
                    self._loc.lines = self.localizer.last_lines
                est = self.localizer.estimate()
                st.pose, st.spread = est.pose.copy(), (est.std_xy_m, est.std_theta_rad)
                # How far the update moved the belief beyond the odometry (the jump test).
                self._loc.correction = (float(st.pose[0] - predicted[0]), float(st.pose[1] - predicted[1]))
        self.guard.note_odometry(st.odom)
        if t is not None and self.view_check is not None and st.fresh and st.depth is not None:
            if self.lost.relocalizing:  # the health monitor does not listen while relocalizing
                self.view_check.store(float(t), st.odom, st.depth)
            else:
                self._loc.view_agree = self.view_check.update(float(t), st.odom, st.depth)
        if t is not None and self.health is not None:
            if self.lost.relocalizing:
                accepted = self.lost.step(float(t))
                if accepted is not None:
                    self._restart_on(accepted, float(t))
            else:
                self.lost.watch(float(t), self._loc.lines, self._loc.correction, self._loc.view_agree)
        self.timings_s["localization"] = time.perf_counter() - t0
        return st.pose

    def _restart_on(self, accepted: Accepted, t: float) -> None:
        """Restart CGR on the accepted place; the navigator re-plans to its goal from there."""
        rec = self.cfg.recovery
        assert self.localizer is not None and self.health is not None
        st = self.state
        pose = accepted.pose
        self.localizer.reset(pose, rec.restart_std_xy_m, rec.restart_std_theta_rad)
        st.pose = pose
        est = self.localizer.estimate()
        st.spread = (est.std_xy_m, est.std_theta_rad)
        self.health.reset(t)
        self.lost.settle_until = t + rec.settle_s
        if self.navigator is not None:
            self.navigator.pose_jumped()
            if self.lost.goal is not None:
                self.navigator.set_goal(self.lost.goal, pose, t)

    # -- recovery ------------------------------------------------------------------------
    @property
    def health_state(self) -> str:
        """ok, blind, lost (the moment it is noticed) or relocalizing; ok without recovery."""
        if self.lost.relocalizing:
            return "relocalizing"
        return "ok" if self.health is None else self.health.state

    @property
    def health_sample(self) -> HealthSample | None:
        """The health monitor's last sample (None without recovery)."""
        return None if self.health is None else self.health.last

    def prepare_recovery(self) -> None:
        """Build the relocalization's map search now rather than at the first alarm
        (:meth:`autonomy.stack.lost.LostRecovery.prepare`)."""
        self.lost.prepare()

    # -- deciding ------------------------------------------------------------------------
    def decide(self, t: float, pose: np.ndarray | None = None) -> NavCommand:
        """The navigator's command at time ``t`` from the last perception, on the estimate
        (or on ``pose``: a simulation's ground-truth follower). Blind (no usable frame
        for a while), the robot stands still; relocalizing, it turns in place to look
        (and, undecided after ``recovery.explore_after_s``, drives on the best mode), and
        goes on turning for ``recovery.settle_s`` after a mode is accepted."""
        nav = self._nav()
        per = self.state.perception
        obstacles = np.zeros((0, 2)) if per is None else per.obstacles
        near = None if per is None else per.near_lines
        t0 = time.perf_counter()
        if self.health is not None and self.health.state == "blind":
            cmd = NavCommand(np.zeros(3), "blind")
        elif self.lost.relocalizing and pose is None:
            cmd = self.lost.motion.command(t, obstacles, near)
        elif pose is None and t < self.lost.settle_until:
            cmd = nav.look_around(t)
            cmd.state = "settling"
        else:
            cmd = nav.command(self.state.pose if pose is None else pose, obstacles, t, near)
        self.timings_s["navigation"] = time.perf_counter() - t0
        return cmd

    def step(
        self,
        depth: np.ndarray | None,
        increment: np.ndarray | None,
        t: float,
        pose: np.ndarray | None = None,
        *,
        seed: int | None = None,
        localize: bool = True,
        operator: Callable[[StackOutput], np.ndarray | None] | None = None,
        correspondences: bool = False,
        known_m: float = 0.0,
    ) -> StackOutput:
        """One frame: perceive ``depth`` (``seed`` as :meth:`perceive`'s), localize on the
        odometry ``increment`` at time ``t``, and (when navigating) decide at ``t`` on the
        estimate, or on ``pose`` (a simulation's ground-truth follower). The output's
        command is for the motion until the next frame.

        ``localize`` False: the frame is perceived and decided on, not localized on (the
        first frame after :meth:`reset`, seen before anything moved: the belief is the
        reset pose, and the recovery's clocks start with the next frame).

        ``operator``: someone watching the belief between the localizing and the deciding
        (a simulation's truth reset; the paper's operator reset the robot by hand). Given
        the frame's output so far (no command), it returns a pose to re-initialise the
        belief at (:meth:`relocalize`) before the decision, or None.

        ``correspondences``: also associate the observation points with the scene lines
        for a viewer that draws them this frame (:meth:`correspondences`: one association
        pass, which no other reader needs); else the output has none. ``known_m`` > 0:
        also what the navigator knows within that radius (:attr:`StackOutput.known`)."""
        self.perceive(depth, seed)
        if localize:
            self.localize(increment, t)
        if operator is not None:
            reset_to = operator(self._output(None, None))
            if reset_to is not None:
                self.relocalize(reset_to)
        cmd = self.decide(t, pose) if self.navigator is not None else None
        return self._output(cmd, pose, correspondences, known_m)

    def redecide(self, t: float, pose: np.ndarray | None = None) -> StackOutput:
        """Decide again on the last frame (after :meth:`set_goal` at the end of a leg): the
        last :meth:`step`'s output with the new command and plan."""
        return self._output(self.decide(t, pose), pose)

    def _output(self, cmd: NavCommand | None, pose: np.ndarray | None, correspondences: bool = False, known_m: float = 0.0) -> StackOutput:
        """The stack now as a :class:`StackOutput` (``pose``: the pose decided on, None:
        the estimate)."""
        st, loc = self.state, self.localizer
        if len(st.events) != len(self._events_out):
            self._events_out = tuple(st.events)
        return StackOutput(
            command=cmd,
            estimate=st.pose.copy(),
            spread=st.spread,
            perception=empty_perception() if st.perception is None else st.perception,
            timings_s=dict(self.timings_s),
            plan=self._plan_view(st.pose if pose is None else pose),
            localizing=loc is not None,
            relocalizing=self.lost.relocalizing,
            health_state=self.health_state,
            health_sample=self.health_sample,
            events=self._events_out,
            frame_fault=self.guard.fault,
            frames_rejected=dict(self.guard.rejected),
            cgr_stats=self._loc.stats,
            correction=self._loc.correction,
            odometry=st.odom.copy(),
            particles=None if loc is None else loc.particles.copy(),
            refinement=None if loc is None else Refinement(loc.before_refinement, loc.after_refinement, loc.refined_weights),
            last_search=self.lost.last_search,
            correspondences=self.correspondences() if correspondences else None,
            known=self.navigator.known_points(st.pose, known_m) if known_m > 0 and self.navigator is not None else None,
        )

    def _plan_view(self, pose: np.ndarray, length_m: float | None = None) -> PlanView | None:
        """The navigator's plan, its metres ahead measured from ``pose`` (or given as
        ``length_m``), and its counters; None without a navigator."""
        nav = self.navigator
        if nav is None:
            return None
        at = None if length_m is not None else np.array(pose[:2], dtype=np.float64)
        length = math.nan if length_m is None else float(length_m)
        return PlanView(nav.plan, at, length, nav.replans, nav.recoveries, nav.blocked_edges)

    # -- goals ---------------------------------------------------------------------------
    def set_goal(self, node_id: int, t: float, pose: np.ndarray | None = None) -> PlanView:
        """Plan to a navigation-graph node from the estimate (or ``pose``); returns the plan
        with its length as the metres ahead. While relocalizing the goal is kept for when
        the robot knows where it is again: the plan returned is the one followed until
        then, the length the best mode's plan's.

        A goal that the place the robot was started at (:meth:`reset`; unknown there,
        the first goal) has no path to is the user's mistake:
        :class:`autonomy.maps.planner.NoPathError`. One that only the belief has no path to
        (a wrong belief in a part of the graph cut off from the goal) is the robot's:
        the plan starts at the nearest node that reaches the goal, and the localization
        recovers the belief (:meth:`Navigator.set_goal`)."""
        nav = self._nav()
        if self._home is None:
            home = nav.graph.node_xy()[nav.graph.index_of(int(node_id))]
            self._home = np.asarray(home, dtype=np.float64).copy()
        elif not nav.reaches(int(node_id), self._home)[0]:
            start = nav.nearest_reachable_node(self._home)
            raise NoPathError(f"no path from node {start} (where the robot started) to node {int(node_id)} in the navigation graph")
        self.lost.goal = int(node_id)
        at = self.state.pose if pose is None else pose
        if self.lost.relocalizing and pose is None:
            length = nav.plan_length(int(node_id), at)
        else:
            length = nav.set_goal(node_id, at, t)
        plan = self._plan_view(at, length)
        assert plan is not None
        return plan

    # -- for viewers ---------------------------------------------------------------------
    def _nav(self) -> Navigator:
        if self.navigator is None:
            raise InputError("robot stack: built with navigate = false, it has no navigator")
        return self.navigator

    def correspondences(self) -> tuple[np.ndarray, np.ndarray]:
        """The scene lines visible from the estimate and, for each observation point, the
        index of the line it is associated with there (-1: none), as CGR's observation
        model associates them (BV2012 Eq. 1). For viewers; costs one association pass."""
        per = self.state.perception
        if self.scene is None or per is None:
            return np.zeros((0, 4)), np.zeros(0, dtype=np.int64)
        est = self.state.pose
        lines = np.ascontiguousarray(self.scene.scene_lines(float(est[0]), float(est[1]))[0])
        return lines, associate(lines, est, per.points_2d, per.normals_2d, self.cfg.localization.observation)
