"""Lost detection and global relocalization on the robot (ours; the papers' operator
re-localized the robot by hand): the health monitor on each frame, and while lost the
scan, the map search and the decision (:mod:`autonomy.localization.health`,
:mod:`autonomy.localization.relocalization`). How the robot moves meanwhile is
:mod:`autonomy.stack.search_motion`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from autonomy.common.geometry import (
    compose_pose,
    relative_pose,
    sensor_view,
    wrap_angle,
)
from autonomy.localization.health import HealthMonitor, explain_points
from autonomy.localization.missing_walls import missing_walls
from autonomy.localization.relocalization import GlobalLocalizer, Mode
from autonomy.localization.straight_runs import on_straight_runs
from autonomy.maps.freespace import FreeSpaceConfig, build_free_space
from autonomy.maps.raycast import SceneQuery
from autonomy.maps.vectormap import VectorMap
from autonomy.navigation.navigator import Navigator
from autonomy.perception.floor_rays import floor_rays
from autonomy.stack.config import StackConfig
from autonomy.stack.lost_view import LostView
from autonomy.stack.search_motion import SearchMotion
from autonomy.stack.state import StackState

#: While relocalizing the modes are re-scored each search, and the whole map searched
#: again every this many searches (the scan has grown; a mode dropped early may win).
#: A mode is only accepted on a search of the whole map: one that passes the decision
#: when re-scored brings the next whole-map search forward.
FULL_SEARCH_EVERY = 5


@dataclass(frozen=True)
class Accepted:
    """A relocalization's decision: the place the robot is at (map frame)."""

    pose: np.ndarray


@dataclass
class SearchProgress:
    """How the searches since the robot got lost went: when the last ran, how many, whether
    the next must cover the whole map, and the candidate place the latest ones agreed on."""

    last_t: float = -math.inf
    """When the last map search ran."""
    searches: int = 0
    """Map searches since the robot got lost."""
    whole_map: bool = False
    """The next search covers the whole map (the candidate was not confirmed)."""
    confirmed: int = 0
    """How many searches in a row gave ``candidate``."""
    candidate: np.ndarray | None = field(default=None)
    """The place the last searches gave (map frame)."""


class LostRecovery:
    """The health monitor's verdict on each frame (:meth:`watch`) and, once lost, the
    relocalization (:meth:`step`, a frame at a time) until a place is accepted; the
    search motion (:attr:`motion`) moves the robot meanwhile."""

    def __init__(
        self,
        cfg: StackConfig,
        state: StackState,
        vectormap: VectorMap,
        scene: SceneQuery | None,
        health: HealthMonitor | None,
        navigator: Navigator | None,
    ) -> None:
        self.cfg = cfg
        self.state = state
        self.vectormap = vectormap
        self.scene = scene
        self.health = health
        self.navigator = navigator
        self.view = LostView(cfg, state, navigator)
        self.relocalizing = False
        """True while the robot is lost and searching the map (it looks round)."""
        self.last_search = None
        """The last map search's result (:class:`autonomy.localization.relocalization.SearchResult`)."""
        self.goal: int | None = None
        """The navigator's goal when the robot got lost: planned again once it knows where it is."""
        self.settle_until = -math.inf
        """After a relocalization the robot turns in place until then (``recovery.settle_s``)."""
        self.missing = (0, 0, 0)
        """The last checked frame's pixels expecting a mapped wall, those of them that
        returned a depth, and those that saw past the wall (:mod:`autonomy.localization.missing_walls`)."""
        self.motion = SearchMotion(cfg, state, self.view, navigator, scene)
        self._global: GlobalLocalizer | None = None
        self._prior: np.ndarray | None = None
        self._prior_trusted = True
        self._progress = SearchProgress()

    # -- the belief while lost -----------------------------------------------------------
    def belief(self, odom: np.ndarray) -> np.ndarray | None:
        """The belief until a mode is accepted: the one before the alarm, dead reckoned
        (a false alarm leaves it right); without one (an unknown start), the best mode so
        far; None before the first search of an unknown start."""
        if self._prior is not None:
            return compose_pose(self._prior, odom)
        if self.view.modes:
            return compose_pose(self.view.modes[0][0], odom)
        return None

    # -- the map search ------------------------------------------------------------------
    def prepare(self) -> None:
        """Build the map search now (the free-space grid, the coarse hypotheses and the
        segment index) and load its kernels (:meth:`GlobalLocalizer.warm`, and the count
        of the scan's wall points) rather than at the first alarm: a long run's memory is
        then steady from its start, and the first search does not wait for it."""
        if self.health is not None and self._global is None:
            self.global_localizer().warm()
            on_straight_runs(np.zeros((2, 2)), 1.0)

    def global_localizer(self) -> GlobalLocalizer:
        """The relocalization's map search on this stack's map (built on first use)."""
        if self._global is None:
            r = self.cfg.avoidance.robot_radius_m
            fs = build_free_space(self.vectormap, FreeSpaceConfig(robot_radius_m=r))
            self._global = GlobalLocalizer(
                fs, r, self.cfg.recovery.relocalization, segments=self.vectormap.segments, sensor_xy=self.view.sensor_xy
            )
        return self._global

    def watch(self, t: float, cgr_lines: np.ndarray | None, correction: tuple[float, float] | None, view_agree: float) -> None:
        """The health monitor on this frame (``cgr_lines``: the scene lines CGR's update
        used, ``correction`` how far it moved the belief beyond the odometry,
        ``view_agree`` the view check's agreement); lost: start relocalizing."""
        assert self.health is not None and self.scene is not None
        st = self.state
        per, hc = st.perception, self.cfg.recovery.health
        verdicts = None
        missing = math.nan
        if st.fresh and per is not None:
            # The lines CGR's update just used (seen from its proposal mean, centimetres
            # from the estimate) serve the check too; a second query costs 0.15 ms.
            lines = cgr_lines
            if lines is None:
                lines = np.ascontiguousarray(self.scene.scene_lines(float(st.pose[0]), float(st.pose[1]))[0])
            at, rel = sensor_view(st.pose, per.points_2d, self.view.sensor_xy)
            verdicts = explain_points(lines, at, rel, hc.explain_m, hc.through_m)
            if st.depth is not None and hc.lost_missing > 0.0:
                cam, mc = self.cfg.camera, self.cfg.recovery.missing
                self.missing = missing_walls(
                    st.depth, lines, st.pose, cam.intrinsics, st.mount.robot_from_camera(), cam.min_range_m, cam.max_range_m, mc
                )
                if self.missing[1] >= mc.min_returned:
                    missing = self.missing[2] / self.missing[1]
        was = self.health.state
        sample = self.health.update(t, verdicts, st.spread[0], correction, view_agree, missing)
        if sample.state != was and "blind" in (sample.state, was) and sample.state != "lost":
            st.events.append({"t": round(t, 3), "event": sample.state if sample.state == "blind" else "seeing"})
        if sample.state == "lost":
            prior = compose_pose(st.pose, relative_pose(st.odom, np.zeros(3)))
            self.start(t, prior, sample.reason)
            # A belief that just jumped is the suspect: it competes with the other places
            # but wins only by the usual margins (a corridor the map repeats fits both).
            self._prior_trusted = sample.reason != "belief jumped"

    def start(self, t: float, prior: np.ndarray | None, why: str) -> None:
        """Lost at ``t``: look round, with the belief before the alarm (``prior``, a
        map-from-odometry transform) as one of the places to compare."""
        self.relocalizing = True
        self.settle_until = -math.inf
        self.view.clear(t)
        self._prior = prior
        self._prior_trusted = True
        self._progress = SearchProgress()
        self.motion.start(t)
        if self.health is not None:
            # Its averages restart when the robot knows where it is again; a blind state
            # from before would keep the robot from turning to look.
            self.health.reset(t)
        if self.navigator is not None:
            self.goal = self.navigator.goal if self.navigator.goal is not None else self.goal
        self.state.events.append({"t": round(t, 3), "event": "lost", "why": why, "estimate": [round(float(v), 3) for v in self.state.pose]})

    def end(self) -> None:
        """Not lost (a place was accepted, or the belief was set from outside)."""
        self.relocalizing = False
        self.view.modes = []
        self._prior = None
        self.motion.end()

    def step(self, t: float) -> Accepted | None:
        """While lost, one frame: grow the scan; once the robot has looked round, search
        the map (then re-score the modes, and search again every few tries, as the scan
        grows). The place accepted, if one is."""
        rc = self.cfg.recovery.relocalization
        st, view = self.state, self.view
        scan = view.scan
        per = st.perception
        if st.fresh and per is not None:
            floor = None
            if rc.floor_weight > 0.0 and st.depth is not None:
                cam = self.cfg.camera
                floor = floor_rays(st.depth, cam.intrinsics, st.mount.robot_from_camera(), rc.floor_stride_px)
            scan.add(st.odom, per.points_2d, t, floor)
            view.keep_near(per.near_lines, t)
        looked = view.swept() or scan.travelled_m >= rc.min_travel_m
        if not looked or t - self._progress.last_t < rc.search_every_s or len(scan.points) < rc.min_scan_points:
            return None
        self._progress.last_t = t
        gl = self.global_localizer()
        assert self.scene is not None
        query = self.scene
        odom = st.odom
        pts = scan.in_robot_frame(odom)
        origins = scan.origins_in_robot_frame(odom)
        floor = scan.floor_in_robot_frame(odom)
        frame_pts = per.points_2d if (st.fresh and per is not None) else None
        prior = None if self._prior is None else compose_pose(self._prior, odom)
        full = not view.modes or self._progress.searches % FULL_SEARCH_EVERY == 0 or self._progress.whole_map
        self._progress.whole_map = False
        times = scan.times
        if full:
            res = gl.search(pts, frame_pts, lambda x, y: query.scene_lines(x, y)[0], prior, origins, times, floor)
        else:
            poses = [compose_pose(T, odom) for T, _ in view.modes]
            if prior is not None:
                poses.append(prior)
            res = gl.rescore(np.array(poses), pts, frame_pts, lambda x, y: query.scene_lines(x, y)[0], origins, times, floor)
        self._progress.searches += 1
        inv = relative_pose(odom, np.zeros(3))
        view.modes = [(compose_pose(m.pose, inv), m.score) for m in res.modes]
        if view.modes and self._prior is None:
            st.pose = compose_pose(view.modes[0][0], odom)
        self.last_search = res
        prior_mode = None
        if prior is not None and res.modes and self._prior_trusted:
            # A false alarm ends where it began: the belief before the alarm, if it still
            # explains the scan about as well as the best mode.
            kept = gl.rescore(prior[None, :], pts, origins=origins, times=times, floor=floor).modes
            if kept and gl.keeps_prior(kept[0], res.modes, len(pts)):
                return self._accept(kept[0], t, f"the belief before the alarm explains the scan (score {kept[0].score:.3f})", len(res.modes))
            prior_mode = kept[0] if kept else None
        acc = res.accepted
        if acc is not None and not gl.lead_allowed(acc, prior_mode):
            acc = None
        if acc is None:
            self._progress.confirmed = 0
            return None
        # Modes compared as map-from-odometry transforms: the robot turns between searches.
        cand = compose_pose(acc.pose, inv)
        prog, before = self._progress, self._progress.candidate
        same = before is not None and math.hypot(*(cand[:2] - before[:2])) < rc.mode_separation_m and abs(
            wrap_angle(float(cand[2] - before[2]))
        ) < math.radians(rc.mode_separation_deg)
        prog.confirmed = prog.confirmed + 1 if same else 1
        prog.candidate = cand
        if prog.confirmed >= rc.confirmations:
            if full:
                return self._accept(acc, t, res.reason, len(res.modes))
            # Re-scoring sees only the modes kept so far; the place the robot is at
            # may not be among them (a room's corner fits hundreds of places).
            self._progress.whole_map = True
        return None

    def _accept(self, mode: Mode, t: float, reason: str, n_modes: int) -> Accepted:
        """The decision: logged, and the relocalization over."""
        pose = np.asarray(mode.pose, dtype=np.float64).copy()
        self.state.events.append(
            {
                "t": round(t, 3), "event": "relocalized", "pose": [round(float(v), 3) for v in pose], "reason": reason,
                "modes": n_modes, "searches": self._progress.searches, "scan_points": len(self.view.scan.points),
                "looked_s": round(t - self.view.started_t, 3),
            }
        )
        self.end()
        return Accepted(pose)
