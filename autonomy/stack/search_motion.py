"""How a lost robot moves (ours): it turns in place to look; looked round with too little
wall in the scan, it drives to find walls; still undecided after
``recovery.explore_after_s``, it drives on the best mode's belief to a place that tells
the modes apart (:mod:`autonomy.localization.active_localization`), then looks again."""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import (
    compose_pose,
    points_in_frame,
    polyline_clear,
    wrap_angle,
    wrap_angles,
)
from autonomy.localization.active_localization import drive_value
from autonomy.maps.raycast import SceneQuery
from autonomy.navigation.avoidance import open_path_lengths
from autonomy.navigation.config import NavCommand
from autonomy.navigation.navigator import Navigator
from autonomy.stack.config import StackConfig
from autonomy.stack.lost_view import SEEN_KEEP_S, LostView
from autonomy.stack.state import StackState

#: An exploring plan may pass this much closer to a scan point than the robot's radius
#: (the Kinect's noise on walls beside the path).
EXPLORE_CLEAR_SLACK_M = 0.05
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


class SearchMotion:
    """The lost robot's commands (:meth:`command`): look round, drive to find walls
    (:meth:`probe`), drive to tell the modes apart (:meth:`explore_node`)."""

    def __init__(self, cfg: StackConfig, state: StackState, view: LostView, navigator: Navigator | None, scene: SceneQuery | None) -> None:
        self.cfg = cfg
        self.state = state
        self.view = view
        self.navigator = navigator
        self.scene = scene
        self.exploring_from: np.ndarray | None = None
        """Dead reckoning where the drive on the best mode set out (None: not driving)."""
        self.explore_T = np.zeros(3)
        """The map-from-odometry transform of the mode that drive set out on."""
        self.explore_t0 = 0.0
        self.explored: set[int] = set()
        """The graph nodes driven to in this relocalization."""
        self.probe: tuple[np.ndarray, float, float] | None = None
        """The drive to find walls: (dead reckoning at its start, heading, start time)."""

    def start(self, t: float) -> None:
        """Lost at ``t``: no drive yet."""
        self.exploring_from = None
        self.explore_t0 = t
        self.explored = set()
        self.probe = None

    def end(self) -> None:
        """Not lost any more: any drive is over."""
        self.exploring_from = None
        self.probe = None

    def command(self, t: float, obstacles: np.ndarray, near: np.ndarray | None) -> NavCommand:
        """Turn in place to look; looked round with too little wall in the scan, drive to
        find walls (:meth:`_probe_motion`); still undecided after ``explore_after_s``,
        drive ``explore_m`` on the best mode's belief, then look again."""
        rec = self.cfg.recovery
        nav = self.navigator
        view = self.view
        odom = self.state.odom
        assert nav is not None
        if self.probe is not None or (view.swept() and view.lacks_walls(t)):
            cmd = self._probe_motion(t, obstacles, near)
            if cmd is not None:
                return cmd
        if not view.modes or t - view.started_t < rec.explore_after_s:
            return nav.look_around(t)
        if self.exploring_from is None:
            best = compose_pose(view.modes[0][0], odom)
            node = self.explore_node(best, t)
            if node is None:
                return nav.look_around(t)
            nav.pose_jumped()
            nav.set_goal(node, best, t)
            self.exploring_from = odom.copy()
            self.explore_T = view.modes[0][0].copy()
            self.explore_t0 = t
            self.explored.add(node)
        # One drive sees the world through the transform of the mode it set out on: the
        # modes are re-scored every second and the best may change, but a plan, the
        # obstacle memory and the map's walls in the camera's blind spots placed through
        # one mode and then read through another would put walls where none are seen.
        best = compose_pose(self.explore_T, odom)
        if self.ruled_out(best):
            # The scan has ruled out the mode this drive set out on: its plan leads
            # nowhere the robot is. Set out at once on the best mode now (the scan
            # already holds the surroundings; no new look round is needed).
            self.exploring_from = None
            return self.command(t, obstacles, near)
        # The scan's walls count with the map's where the camera cannot look: the map is
        # placed through a mode that may be wrong (a door beside the robot that the
        # mode's map has elsewhere).
        cmd = nav.command(best, obstacles, t, near, seen=view.seen_now(t, best))
        gone = math.hypot(*(odom[:2] - self.exploring_from[:2]))
        if cmd.state == "arrived" or gone >= rec.explore_m or t - self.explore_t0 > rec.explore_timeout_s:
            # Look round again from here (the scan keeps what it saw on the way).
            self.exploring_from = None
            view.look_again(t)
            return nav.look_around(t)
        cmd.state = "exploring" if cmd.state in ("driving", "turning") else cmd.state
        return cmd

    def _probe_motion(self, t: float, obstacles: np.ndarray, near: np.ndarray | None) -> NavCommand | None:
        """Looked round without seeing enough wall to search the map by
        (:meth:`LostView.lacks_walls`: in a hall whose walls all lie beyond the
        camera's 4 m the scan holds a pillar or two, or pillars and furniture the map
        lacks, which fit no place clearly), drive to find walls: on dead reckoning alone,
        the way the scan shows most open (Eq. 3's open path length on what the robot has
        seen, :meth:`LostView.seen_now`, every ``360 / PROBE_BEARINGS`` degrees up to
        ``explore_m``; of the ways as open as the most, the one nearest ahead): the walls
        lie beyond the camera's range that way, and a way towards what the scan holds can
        end at a chair. It avoids what the camera sees, until the scan holds enough wall,
        ``explore_m`` is behind or ``explore_timeout_s`` has passed; then it looks round
        again (None: the caller does). The searches go on meanwhile, and one that decides
        ends the drive. The next probe sets out from where this one ended, the way most
        open from there."""
        rec = self.cfg.recovery
        nav = self.navigator
        view = self.view
        odom = self.state.odom
        assert nav is not None
        if self.probe is None:
            rel = most_open_way(view.seen_now(t), self.cfg.avoidance.robot_radius_m, rec.explore_m)
            self.probe = (odom.copy(), wrap_angle(float(odom[2]) + rel), t)
            # The memory and trail were placed through the belief before the alarm; this
            # drive sees the world in the odometry's frame.
            nav.pose_jumped()
        start, heading, t0 = self.probe
        gone = math.hypot(float(odom[0] - start[0]), float(odom[1] - start[1]))
        if not view.lacks_walls(t) or gone >= rec.explore_m or t - t0 > rec.explore_timeout_s:
            self.probe = None
            view.look_again(t)
            nav.pose_jumped()
            return None
        cmd = nav.head_for(odom, heading, obstacles, t, near, seen=view.seen_now(t))
        cmd.state = "exploring" if cmd.state in ("driving", "turning") else cmd.state
        return cmd

    def ruled_out(self, pose: np.ndarray) -> bool:
        """Whether no mode near ``pose`` (within the modes' separation) scores within
        ``recovery.active.abandon_margin`` of the best mode."""
        modes = self.view.modes
        if not modes:
            return False
        rc = self.cfg.recovery.relocalization
        limit = modes[0][1] + self.cfg.recovery.active.abandon_margin
        sep = math.radians(rc.mode_separation_deg)
        odom = self.state.odom
        for T, score in modes:
            if score > limit:
                break
            p = compose_pose(T, odom)
            if math.hypot(p[0] - pose[0], p[1] - pose[1]) < rc.mode_separation_m and abs(wrap_angle(float(p[2] - pose[2]))) < sep:
                return False
        return True

    def explore_node(self, pose: np.ndarray, t: float) -> int | None:
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
        fresh = ~np.isin(ids, np.array(sorted(self.explored), dtype=np.int64))
        if fresh.any():  # a place not tried yet (the last one may have been blocked)
            cand = cand[fresh]
        if not len(cand):
            return None
        bearing = np.abs(wrap_angles(np.arctan2(xy[cand, 1] - pose[1], xy[cand, 0] - pose[0]) - pose[2]))
        order = cand[np.argsort(bearing, kind="stable")]
        seen = self.view.scan.recent_in_robot_frame(self.state.odom, t - SEEN_KEEP_S)
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
        modes = self.view.modes
        if not act.enabled or not modes:
            return np.zeros((0, 3))
        top = modes[0][1]
        others = [compose_pose(T, self.state.odom) for T, s in modes[1 : act.modes] if s <= top + act.score_margin]
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
