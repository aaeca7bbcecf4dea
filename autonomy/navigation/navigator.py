"""Waypoint navigation: global plan on the nav graph, carrot following, avoidance, recovery.

The navigator reads only a pose (the localization estimate in the loop) and the obstacle
points the depth camera sensed (robot frame, down-projected); it never sees ground truth.
Per frame it:

1. projects the pose on the planned polyline and puts a carrot ``lookahead_m`` further on
   (``narrow_lookahead_m`` on and before doors, so that it enters them straight);
2. if the carrot is far off the heading, turns in place first (the Kinect sees only
   +-29 degrees, so the robot must look where it is going);
3. otherwise asks the obstacle avoidance (BV2012, Eq. 3-5) for the direction theta*
   closest to the carrot with the longest open path, and a speed that can stop within it
   (and, ours, no faster than ``corner_speed_mps`` round the plan's corners nor than
   the graph edge's ``max_speed``; map walls in the camera's blind spots count as
   obstacles, ``map_blind_spots_m``);
4. watches progress: no progress for ``stuck_time_s`` triggers a recovery (back off
   briefly, then re-plan from the nearest reachable node); the graph edges where what
   blocks the robot stands are left out of the plans for ``blocked_edge_s``, so the
   re-plan goes round a corridor that a box or a closed door (not in the map) blocks.

A back-off (the camera does not look behind the robot) goes only over the robot's own
recent trail, where it has been (``trail_s``); else the robot turns in place towards its
plan, so that the camera looks before the robot drives (or, stuck with the plan still
leading the blocked way, turns round to look back and drives away that way,
``look_back_m``).

Obstacles are remembered for ``memory_s`` in the world frame (through the pose
estimate) while they are out of the camera's view: with a 58 degree field of view and
nothing seen closer than 0.8 m, a person the robot is passing is otherwise forgotten
exactly when it matters (ours; ``memory_s = 0`` reacts to the current frame only, as
the paper).
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import (
    wrap_angle,
)
from autonomy.maps.vectormap import NavGraph
from autonomy.navigation.avoidance import (
    AvoidanceConfig,
    AvoidanceResult,
    choose_direction,
)
from autonomy.navigation.config import NavCommand, NavigatorConfig
from autonomy.navigation.plan import Plan
from autonomy.navigation.route import RoutePlanner
from autonomy.navigation.steering import Steering, turn_rate
from autonomy.navigation.surroundings import Surroundings
from autonomy.navigation.trail import Trail
from autonomy.perception.camera import KINECT_V1, DepthCamera
from autonomy.perception.nearfield import line_points

_LOOK_BACK_FACING_RAD = math.radians(10.0)
"""A look back drives once the robot faces the way back this closely."""


class Navigator:
    """Drives to nav-graph goals on a pose estimate, avoiding sensed obstacles.

    ``camera``: the depth camera's field of view, mount and valid range, which decide
    what the robot can see now (the obstacle memory, the map's blind spots, look-first).
    """

    def __init__(
        self,
        graph: NavGraph,
        cfg: NavigatorConfig = NavigatorConfig(),
        avoid: AvoidanceConfig = AvoidanceConfig(),
        walls: np.ndarray | None = None,
        camera: DepthCamera = KINECT_V1,
    ) -> None:
        self.graph = graph
        self.cfg = cfg
        self.avoid = avoid
        self.camera = camera
        walls = None if walls is None else np.asarray(walls, dtype=np.float64).reshape(-1, 4)
        self.route = RoutePlanner(graph, cfg, avoid, walls, camera)
        """Plans on the graph and the edges marked blocked."""
        self.plan = Plan(cfg, avoid.robot_radius_m)
        """The plan followed (none until :meth:`set_goal`)."""
        self.surroundings = Surroundings(cfg, avoid, camera, walls)
        """The map's walls near the robot and the obstacle memory."""
        self._best_s = 0.0
        self._progress_t = 0.0
        self._backoff_until = -1.0
        self._backoff_started = -np.inf
        self._stuck_backoff = False
        self.replans = 0
        self.recoveries = 0
        self._look_back: tuple[float, np.ndarray | None, float] | None = None
        """A look back under way (``look_back_m``): the heading to face, where the drive
        that way began (None while turning) and when it ends at the latest."""
        self._t = 0.0
        """Time of the last frame (``command``)."""
        self.trail = Trail(cfg)
        """The robot's footprints (``trail_s``), along which a back-off goes."""
        self.steering = Steering(cfg, avoid, camera, self.surroundings)
        """The carrot, the direction and the speed."""

    @property
    def goal(self) -> int | None:
        """The goal node; None before :meth:`set_goal`."""
        return self.plan.goal

    @property
    def path(self) -> np.ndarray:
        """The plan's polyline (K, 2), world frame, the pose it was made from first."""
        return self.plan.path

    @property
    def plan_nodes(self) -> list[int]:
        """The plan's graph nodes (the plan runs from the pose to the first of them, then on)."""
        return self.plan.nodes

    @property
    def blocked(self) -> dict[tuple[int, int], float]:
        """The edges marked blocked now and when each mark expires (:attr:`RoutePlanner.blocked`)."""
        return self.route.blocked

    @property
    def blocked_edges(self) -> int:
        """Edges marked blocked so far (a mark renewed is not counted)."""
        return self.route.blocked_edges

    def nearest_reachable_node(self, xy: np.ndarray, avoid: np.ndarray | None = None, goal_id: int | None = None) -> int:
        """:meth:`RoutePlanner.nearest_reachable_node`."""
        return self.route.nearest_reachable_node(xy, avoid, goal_id)

    def reaches(self, goal_ids, pose: np.ndarray) -> np.ndarray:
        """Which of the goals a plan from the pose sets out to without going through a
        map wall (:meth:`RoutePlanner.reaches`)."""
        return self.route.reaches(goal_ids, pose)

    def set_goal(self, goal_id: int, pose: np.ndarray, t: float = 0.0) -> float:
        """Plan from the pose to a node (:meth:`RoutePlanner.plan_to`: round the edges
        marked blocked while another way is left, from the nearest node in reach that has
        a path to the goal) and start the stuck clock at ``t``; returns the plan's length
        in metres."""
        self.plan = self.route.plan_to(goal_id, pose, t)
        self._best_s = 0.0
        self._progress_t = t
        return self.plan.length_m

    def plan_points(self, goal_id: int, pose: np.ndarray) -> np.ndarray:
        """The polyline of the plan :meth:`set_goal` would make from the pose, without making it."""
        return self.route.plan_points(goal_id, pose)

    def plan_length(self, goal_id: int, pose: np.ndarray) -> float:
        """Length (m) of the plan :meth:`set_goal` would make from the pose, without
        making it (the stack asks while it relocalizes)."""
        return self.route.plan_length(goal_id, pose)

    def _set_plan(self, goal_id: int, nodes: list[int], pose: np.ndarray, t: float) -> None:
        """Make the path from the pose through ``nodes`` the plan and start the stuck clock at ``t``."""
        self.plan = self.route.plan(goal_id, nodes, pose)
        self._best_s = 0.0
        self._progress_t = t

    def remaining_m(self, pose: np.ndarray) -> float:
        """Length of the plan still ahead of the pose; 0 without a plan."""
        return self.plan.remaining_m(np.asarray(pose[:2], dtype=np.float64))

    def _backoff_velocity(self, pose: np.ndarray, obstacles: np.ndarray) -> np.ndarray:
        """Recovery motion: back off the way the robot came, where nothing is in the way.

        Behind the robot the camera sees nothing, so with the trail on (``trail_s``) the
        robot only retraces its own trail (:meth:`retrace`): the space its body has just
        swept is the only evidence there is that the way back is free. A straight line
        near the trail is not enough: a robot that passed a person at a door jamb with
        millimetres to spare, whom the jamb had hidden from the camera, touches them
        backing off straight 5 cm beside the way it came. The way back is taken when its
        first stretch runs within 75 degrees of straight back and the map's walls and the
        remembered obstacles keep ``backoff_clearance_m`` from it (someone may have
        stepped in since); else no translation (the robot re-plans where it stands).
        With the trail off: straight back if that holds for ``backoff_check_m``, else the
        nearest such direction within 75 degrees of it (the map and memory only).
        """
        cfg = self.cfg
        pts = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
        walls = self.surroundings.map_points(pose, cfg.backoff_check_m + self.avoid.robot_radius_m + 0.2)
        pts = np.vstack([pts, walls, self.surroundings.remembered])
        clear = self.avoid.robot_radius_m + cfg.backoff_clearance_m
        if cfg.trail_s > 0:
            return self.trail.retrace_velocity(pose, pts, clear, self._t)
        for k in (0, 1, -1, 2, -2, 3, -3, 4, -4, 5, -5):
            phi = math.pi + k * math.radians(15.0)
            u = np.array([math.cos(phi), math.sin(phi)])
            ahead = pts[pts @ u > 0.0] if len(pts) else pts  # what lies the other way never blocks
            if len(ahead):
                along = np.clip(ahead @ u, 0.0, cfg.backoff_check_m)
                if float(np.min(np.hypot(ahead[:, 0] - along * u[0], ahead[:, 1] - along * u[1]))) < clear:
                    continue
            return np.array([cfg.backoff_speed_mps * u[0], cfg.backoff_speed_mps * u[1], 0.0])
        return np.zeros(3)

    # -- the trail, blocked edges, looking round, pose jumps ----------------------------
    def trail_points(self, t: float | None = None) -> np.ndarray:
        """The trail: the robot's footprints (pose estimates, world frame, oldest first)
        of the ``trail_s`` before ``t`` (default: the last frame's time)."""
        return self.trail.points(self._t if t is None else float(t))

    def retrace(self, pose: np.ndarray) -> np.ndarray:
        """The way back along the trail from the pose, as of the last frame
        (:meth:`Trail.retrace`): what a back-off drives."""
        return self.trail.retrace(pose, self._t)

    def look_around(self, t: float) -> NavCommand:
        """Turn in place at ``look_turn_rate_rad_s`` (state "looking"), no translation:
        the camera sweeps the walls round the robot (while the localization searches
        for it). The stuck clock holds and a back-off under way ends."""
        self._t = float(t)
        self._progress_t = float(t)
        self._backoff_until = -1.0
        self._backoff_started = -np.inf
        self._look_back = None
        return NavCommand(np.array([0.0, 0.0, self.cfg.look_turn_rate_rad_s]), "looking")

    def head_for(
        self, pose: np.ndarray, heading: float, obstacles: np.ndarray, t: float, near_lines: np.ndarray | None = None, seen: np.ndarray | None = None
    ) -> NavCommand:
        """Drive along the world ``heading`` (in the frame of ``pose``) with no plan and
        no map: a robot that does not know where it is, in a hall whose walls lie beyond
        the camera's range, drives to find some (ours). Turn in place to face the
        heading, then Eq. 3-5 on what the camera, the memory and the near field show,
        with the points of ``seen`` (robot frame; the relocalization's scan) in the
        camera's blind spots standing in for the map's walls, which cannot be placed
        without a pose. Blocked, the robot waits turning towards the heading."""
        cfg = self.cfg
        self.surroundings.seen = np.zeros((0, 2))
        self._t = float(t)
        self._progress_t = float(t)
        obstacles = self.surroundings.remember(pose, obstacles, t)
        # Every near-field sight line counts: no map wall can be placed to explain one.
        lines = np.zeros((0, 4)) if near_lines is None else np.asarray(near_lines, dtype=np.float64).reshape(-1, 4)
        near = line_points(lines, self.avoid.near_field.point_step_m)
        if len(near):
            obstacles = np.vstack([obstacles, near])
        xy = np.asarray(pose[:2], dtype=np.float64)
        carrot = xy + cfg.lookahead_m * np.array([math.cos(heading), math.sin(heading)])
        desired = wrap_angle(heading - float(pose[2]))
        turn = turn_rate(cfg, desired)
        if abs(desired) > cfg.turn_in_place_rad:
            return NavCommand(np.array([0.0, 0.0, turn]), "turning", carrot=carrot, desired_rad=desired)
        static = np.zeros((0, 2))
        if seen is not None and cfg.map_blind_spots_m > 0:
            static = np.asarray(seen, dtype=np.float64).reshape(-1, 2)
            static = self.surroundings.out_of_view(static[static[:, 0] ** 2 + static[:, 1] ** 2 < cfg.map_blind_spots_m**2])
        res = self.steering.keep_side(
            choose_direction(obstacles, desired, self.avoid, static, self.avoid.robot_radius_m + cfg.map_clearance_m), desired
        )
        if res.blocked:
            return NavCommand(np.array([0.0, 0.0, turn]), "blocked", carrot, desired, res.theta_star, res.open_length_m, (res.angles, res.lengths))
        return self.steering.drive(obstacles, carrot, desired, min(cfg.cruise_speed_mps, res.safe_speed_mps), res)

    def pose_jumped(self, pose: np.ndarray | None = None, t: float | None = None) -> None:
        """The pose estimate jumped (the robot was re-localized elsewhere): forget what
        was placed through the old estimate -- the obstacle memory, the trail, the lane
        and side chosen -- and a back-off under way; given the new ``pose`` and with a
        goal set, re-plan from it (at ``t``, default the last frame's time). Blocked
        edges stay marked (they expire, and are forgotten when they leave no path)."""
        self.surroundings.forget()
        self.trail.clear()
        self.steering.forget()
        self._backoff_until = -1.0
        self._backoff_started = -np.inf
        self._stuck_backoff = False
        self._look_back = None
        if pose is not None and self.goal is not None:
            self.replans += 1
            self.set_goal(self.goal, pose, self._t if t is None else float(t))

    # -- control -----------------------------------------------------------------------
    def walls_explain(self, pose: np.ndarray, lines: np.ndarray, with_seen: bool = True) -> np.ndarray:
        """Per near-field sight line: whether a wall passes within ``near_wall_tol_m`` of
        it at the pose (:meth:`Surroundings.walls_explain`)."""
        return self.surroundings.walls_explain(pose, lines, with_seen)

    def command(
        self, pose: np.ndarray, obstacles: np.ndarray, t: float, near_lines: np.ndarray | None = None, seen: np.ndarray | None = None
    ) -> NavCommand:
        """Body-frame velocity for this frame from the pose estimate and sensed obstacles.

        ``near_lines``: this frame's near-field sight lines (:mod:`autonomy.perception.nearfield`),
        obstacles closer than the camera's minimum range; they join the obstacles for this
        frame only (the next frame tells again whether they are still there).
        ``seen``: wall points the robot has seen before, robot frame (the relocalization's
        scan while it explores on a mode whose map may be wrong); they count with the
        map's walls where the camera cannot look (:meth:`Surroundings.map_points`).
        """
        self.surroundings.seen = np.zeros((0, 2)) if seen is None else np.asarray(seen, dtype=np.float64).reshape(-1, 2)
        self._t = float(t)
        self.trail.record(pose, t)
        if self.route.blocked:
            self.route.prune_blocked(t)
        obstacles = self.surroundings.remember(pose, obstacles, t)
        located = obstacles
        near = self.surroundings.near_points(pose, near_lines)
        if len(near):
            obstacles = np.vstack([obstacles, near])
        out = self._decide(pose, obstacles, t, located)
        out.near_points = len(near)
        return out

    def _decide(self, pose: np.ndarray, obstacles: np.ndarray, t: float, located: np.ndarray | None = None) -> NavCommand:
        """``located``: the obstacles whose place is known (not the near field's sight
        lines, which say only that something is closer than the camera sees): the lane
        shift goes round those; the near field makes the robot stop and look instead."""
        cfg = self.cfg
        if self.goal is None or len(self.plan.path) < 2:
            return NavCommand(np.zeros(3), "idle")
        xy = np.asarray(pose[:2], dtype=np.float64)
        goal_xy = self.plan.path[-1]
        to_goal = float(np.hypot(*(goal_xy - xy)))
        if to_goal < cfg.arrival_radius_m:
            return NavCommand(np.zeros(3), "arrived", carrot=goal_xy)
        if self._look_back is not None:
            backing = self._continue_look_back(pose, obstacles, t)
        else:
            backing = self._continue_backoff(pose, obstacles, t, obstacles if located is None else located)
        if backing is not None:
            return backing
        s = self.plan.project(xy)
        if self._stuck(s, t):
            return self._start_recovery(pose, obstacles, t, located)
        carrot = self.steering.carrot(self.plan, pose, s, obstacles if located is None else located)
        d = carrot - xy
        desired = wrap_angle(math.atan2(d[1], d[0]) - float(pose[2]))
        turn = turn_rate(cfg, desired)
        if abs(desired) > cfg.turn_in_place_rad:
            return NavCommand(np.array([0.0, 0.0, turn]), "turning", carrot=carrot, desired_rad=desired)
        res = self.steering.choose_direction(pose, obstacles, desired, self.plan.lookahead(s) < cfg.lookahead_m)
        if res.blocked:
            return self._when_blocked(pose, obstacles, t, carrot, desired, turn, res, located)
        speed = min(cfg.cruise_speed_mps, res.safe_speed_mps, 0.8 * to_goal + 0.05, self.plan.corner_speed_limit(s), self.plan.edge_speed_limit(s))
        return self.steering.drive(obstacles, carrot, desired, speed, res)

    def _continue_backoff(self, pose: np.ndarray, obstacles: np.ndarray, t: float, located: np.ndarray) -> NavCommand | None:
        """The back-off's command while it goes on; None once it is over.

        Back off at least backoff_time_s, and on until what blocked the way is in the
        camera's view again (or max_backoff_s has passed), unless there is no way back.
        After a stuck recovery's back-off the stuck clock starts again (run on through a
        long back-off, it would send the robot from one recovery straight into the next,
        for ever, where it cannot back off); a back-off from a blind block counts as no
        progress. Where it may not back off (:meth:`_backoff_velocity`), the robot turns
        in place towards its plan until ``backoff_time_s`` is over. A back-off from a
        blind block that goes on without progress re-plans round the block
        (:meth:`_replan_round_block`; ``located``: the obstacles whose place is known)
        and ends."""
        cfg = self.cfg
        if not (t < self._backoff_until or (t - self._backoff_started < cfg.max_backoff_s and self.surroundings.blind_blocked(obstacles))):
            return None
        if not self._stuck_backoff and self._replan_round_block(pose, located, t):
            self._backoff_until = -1.0
            self._backoff_started = -np.inf
            carrot, desired, omega = self.steering.toward_plan(self.plan, pose)
            return NavCommand(np.array([0.0, 0.0, omega]), "turning", carrot, desired)
        v = self._backoff_velocity(pose, obstacles)
        if self._stuck_backoff:
            self._progress_t = t
        if v.any():
            return NavCommand(v, "recovering")
        if t < self._backoff_until:
            return NavCommand(np.array([0.0, 0.0, self.steering.toward_plan(self.plan, pose)[2]]), "recovering")
        self._backoff_started = -np.inf
        return None

    def _stuck(self, s: float, t: float) -> bool:
        """Record progress along the plan (arc length ``s``); True when there has been
        none for ``stuck_time_s``."""
        cfg = self.cfg
        if s > self._best_s + cfg.stuck_progress_m:
            self._best_s = s
            self._progress_t = t
            return False
        return t - self._progress_t > cfg.stuck_time_s

    def _start_recovery(self, pose: np.ndarray, obstacles: np.ndarray, t: float, located: np.ndarray | None = None) -> NavCommand:
        """Recovery: mark the edges what blocks the robot stands on (``located``, the
        obstacles whose place is known; :meth:`_mark_blocked`), re-plan without them,
        and back off; where the robot may not (:meth:`_backoff_velocity`), turn in place
        towards the new plan, or, when that still leads ahead, look back
        (``look_back_m``, :meth:`_continue_look_back`)."""
        cfg = self.cfg
        self.recoveries += 1
        self._backoff_until = t + cfg.backoff_time_s
        self._backoff_started = t
        self._stuck_backoff = True
        self.replans += 1
        assert self.goal is not None
        self.route.mark_unless_put_off(self.plan, pose, obstacles if located is None else located, t, self.surroundings)
        self.set_goal(self.goal, pose, t + cfg.backoff_time_s)
        v = self._backoff_velocity(pose, obstacles)
        if v.any():
            return NavCommand(v, "recovering")
        _, desired, omega = self.steering.toward_plan(self.plan, pose)
        if cfg.look_back_m > 0 and abs(desired) <= cfg.turn_in_place_rad:
            turn_s = math.pi / cfg.max_turn_rate_rad_s
            drive_s = cfg.look_back_m / max(cfg.backoff_speed_mps, 1e-9)
            self._look_back = (wrap_angle(float(pose[2]) + math.pi), None, t + 2.0 * turn_s + drive_s)
            return self._continue_look_back(pose, obstacles, t) or NavCommand(np.array([0.0, 0.0, omega]), "recovering")
        return NavCommand(np.array([0.0, 0.0, omega]), "recovering")

    def _continue_look_back(self, pose: np.ndarray, obstacles: np.ndarray, t: float) -> NavCommand | None:
        """The look back's command (``look_back_m``); None once it is over. Turn in place
        to face the way back; then drive that way as forward driving does -- Eq. 5 on what
        the camera, the memory and the near field show, in the camera's view only, at
        ``backoff_speed_mps`` at most -- until ``look_back_m`` is behind, the way is
        blocked or the time is up. The stuck clock starts again after it."""
        cfg = self.cfg
        assert self._look_back is not None
        heading, start, until = self._look_back
        self._progress_t = t
        xy = np.asarray(pose[:2], dtype=np.float64)
        err = wrap_angle(heading - float(pose[2]))
        if t > until or (start is not None and math.hypot(xy[0] - start[0], xy[1] - start[1]) >= cfg.look_back_m):
            self._look_back = None
            return None
        if start is None:
            if abs(err) > _LOOK_BACK_FACING_RAD:
                return NavCommand(np.array([0.0, 0.0, turn_rate(cfg, err)]), "recovering")
            self._look_back = (heading, xy.copy(), until)
        res = self.steering.choose_direction(pose, obstacles, err)
        if res.blocked:
            self._look_back = None
            return None
        th = res.theta_star
        omega = turn_rate(cfg, th)
        fan = (res.angles, res.lengths)
        if abs(th) > 0.5 * self.camera.fov_h_rad:
            return NavCommand(np.array([0.0, 0.0, omega]), "recovering", theta_star_rad=th, open_length_m=res.open_length_m, fan=fan)
        speed = min(cfg.backoff_speed_mps, res.safe_speed_mps)
        v = np.array([speed * math.cos(th), speed * math.sin(th), omega])
        return NavCommand(v, "recovering", theta_star_rad=th, open_length_m=res.open_length_m, fan=fan)

    def _when_blocked(
        self,
        pose: np.ndarray,
        obstacles: np.ndarray,
        t: float,
        carrot: np.ndarray,
        desired: float,
        turn: float,
        res: AvoidanceResult,
        located: np.ndarray | None = None,
    ) -> NavCommand:
        """No direction is open: after ``blocked_wait_s`` without progress with the
        obstacle on the plan's line (``located``), mark its edges blocked and re-plan;
        else back off if what blocks is too close for the camera to see, else wait
        turning towards the carrot."""
        fan = (res.angles, res.lengths)
        if self._replan_round_block(pose, obstacles if located is None else located, t):
            carrot, desired, omega = self.steering.toward_plan(self.plan, pose)
            return NavCommand(np.array([0.0, 0.0, omega]), "blocked", carrot, desired, res.theta_star, res.open_length_m, fan)
        back = self._backoff_velocity(pose, obstacles) if self.surroundings.blind_blocked(obstacles) else np.zeros(3)
        if back.any():
            # What blocks is too close for the camera to see: back off until it can
            # look again (a person may have moved on; else it is seen and avoided).
            self._backoff_until = t + self.cfg.backoff_time_s
            self._backoff_started = t
            self._stuck_backoff = False
            return NavCommand(back, "recovering", carrot, desired, res.theta_star, res.open_length_m, fan)
        # Wait (turning towards the carrot): people step aside; stuck detection recovers.
        return NavCommand(np.array([0.0, 0.0, turn]), "blocked", carrot, desired, res.theta_star, res.open_length_m, fan)

    def _replan_round_block(self, pose: np.ndarray, located: np.ndarray, t: float) -> bool:
        """Blocked without progress for ``blocked_wait_s``: re-plan round the edges the
        obstacle stands on (:meth:`RoutePlanner.replan_round_block`). True when the plan
        goes round them; else the plan and the stuck clock stay as they were."""
        nodes = self.route.replan_round_block(self.plan, pose, located, t, self._progress_t, self.surroundings)
        if nodes is None:
            return False
        assert self.goal is not None
        self.replans += 1
        self._set_plan(self.goal, nodes, pose, t)
        return True
