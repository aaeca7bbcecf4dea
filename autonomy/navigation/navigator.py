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

The :class:`Navigator` composes the parts, each in a module of its own, and arbitrates
the command: :mod:`~autonomy.navigation.config` (the parameters and the command),
:mod:`~autonomy.navigation.route` (plans on the graph, the blocked edges),
:mod:`~autonomy.navigation.plan` (the plan followed), :mod:`~autonomy.navigation.surroundings`
(the map's walls near the robot, the obstacle memory), :mod:`~autonomy.navigation.trail`,
:mod:`~autonomy.navigation.steering` (carrot, lane shift, Eq. 5, speed) and
:mod:`~autonomy.navigation.recovery` (the stuck clock, back-off, look back).
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import wrap_angle
from autonomy.maps.navgraph import NavGraph
from autonomy.navigation.avoidance import AvoidanceConfig, choose_direction
from autonomy.navigation.config import NavCommand, NavigatorConfig
from autonomy.navigation.plan import Plan
from autonomy.navigation.recovery import Recovery
from autonomy.navigation.route import RoutePlanner
from autonomy.navigation.steering import Steering, turn_rate
from autonomy.navigation.surroundings import Surroundings
from autonomy.navigation.trail import Trail
from autonomy.perception.camera import KINECT_V1, DepthCamera
from autonomy.perception.nearfield import line_points


class Navigator:
    """Drives to nav-graph goals on a pose estimate, avoiding sensed obstacles.

    ``camera``: the depth camera's field of view, mount and valid range, which decide
    what the robot can see now (the obstacle memory, the map's blind spots, look-first).
    The parts are :attr:`route`, :attr:`plan` (replaced on every re-plan),
    :attr:`surroundings`, :attr:`trail`, :attr:`steering` and :attr:`recovery`.
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
        self.surroundings = Surroundings(cfg, avoid, camera, walls)
        self.trail = Trail(cfg)
        self.steering = Steering(cfg, avoid, camera, self.surroundings)
        self.recovery = Recovery(cfg, avoid, camera, self.surroundings, self.trail, self.steering)
        self.plan = Plan(cfg, avoid.robot_radius_m)
        """The plan followed (none until :meth:`set_goal`)."""
        self.replans = 0
        self.known = np.zeros((0, 2))
        """The obstacles of the last decision, robot frame (:meth:`known_points`)."""
        """Plans made again to the same goal (recoveries, re-plans round a block, pose jumps)."""
        self._t = 0.0
        """Time of the last frame (``command``)."""

    # -- what other code reads ----------------------------------------------------------
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

    @property
    def recoveries(self) -> int:
        """Recoveries started (``stuck_time_s``)."""
        return self.recovery.recoveries

    def nearest_reachable_node(self, xy: np.ndarray, avoid: np.ndarray | None = None, goal_id: int | None = None) -> int:
        """:meth:`RoutePlanner.nearest_reachable_node`."""
        return self.route.nearest_reachable_node(xy, avoid, goal_id)

    def reaches(self, goal_ids, pose: np.ndarray) -> np.ndarray:
        """Which of the goals a plan from the pose sets out to without going through a
        map wall (:meth:`RoutePlanner.reaches`)."""
        return self.route.reaches(goal_ids, pose)

    def plan_points(self, goal_id: int, pose: np.ndarray) -> np.ndarray:
        """The polyline of the plan :meth:`set_goal` would make from the pose, without making it."""
        return self.route.plan_points(goal_id, pose)

    def plan_length(self, goal_id: int, pose: np.ndarray) -> float:
        """Length (m) of the plan :meth:`set_goal` would make from the pose, without
        making it (the stack asks while it relocalizes)."""
        return self.route.plan_length(goal_id, pose)

    def remaining_m(self, pose: np.ndarray) -> float:
        """Length of the plan still ahead of the pose; 0 without a plan."""
        return self.plan.remaining_m(np.asarray(pose[:2], dtype=np.float64))

    def trail_points(self, t: float | None = None) -> np.ndarray:
        """The trail: the robot's footprints (pose estimates, world frame, oldest first)
        of the ``trail_s`` before ``t`` (default: the last frame's time)."""
        return self.trail.points(self._t if t is None else float(t))

    def retrace(self, pose: np.ndarray) -> np.ndarray:
        """The way back along the trail from the pose, as of the last frame
        (:meth:`Trail.retrace`): what a back-off drives."""
        return self.trail.retrace(pose, self._t)

    def known_points(self, pose: np.ndarray, radius_m: float) -> np.ndarray:
        """What the navigator knows to be round the robot within ``radius_m``, robot frame
        of ``pose``: the obstacles of its last decision (the obstacle memory with this
        frame's obstacles, and the near field) and the map's walls through the pose."""
        k = self.known
        k = k[k[:, 0] * k[:, 0] + k[:, 1] * k[:, 1] < radius_m * radius_m]
        return np.vstack([k, self.surroundings.map_points(pose, radius_m, with_seen=False)])

    def walls_explain(self, pose: np.ndarray, lines: np.ndarray, with_seen: bool = True) -> np.ndarray:
        """Per near-field sight line: whether a wall passes within ``near_wall_tol_m`` of
        it at the pose (:meth:`Surroundings.walls_explain`)."""
        return self.surroundings.walls_explain(pose, lines, with_seen)

    # -- goals ----------------------------------------------------------------------------
    def set_goal(self, goal_id: int, pose: np.ndarray, t: float = 0.0) -> float:
        """Plan from the pose to a node (:meth:`RoutePlanner.plan_to`: round the edges
        marked blocked while another way is left, from the nearest node in reach that has
        a path to the goal) and start the stuck clock at ``t``; returns the plan's length
        in metres."""
        self.plan = self.route.plan_to(goal_id, pose, t)
        self.recovery.restart(t)
        return self.plan.length_m

    def pose_jumped(self, pose: np.ndarray | None = None, t: float | None = None) -> None:
        """The pose estimate jumped (the robot was re-localized elsewhere): forget what
        was placed through the old estimate -- the obstacle memory, the trail, the lane
        and side chosen -- and a back-off under way; given the new ``pose`` and with a
        goal set, re-plan from it (at ``t``, default the last frame's time). Blocked
        edges stay marked (they expire, and are forgotten when they leave no path)."""
        self.surroundings.forget()
        self.known = np.zeros((0, 2))
        self.trail.clear()
        self.steering.forget()
        self.recovery.forget()
        if pose is not None and self.plan.goal is not None:
            self.replans += 1
            self.set_goal(self.plan.goal, pose, self._t if t is None else float(t))

    # -- commands -------------------------------------------------------------------------
    def look_around(self, t: float) -> NavCommand:
        """Turn in place at ``look_turn_rate_rad_s`` (state "looking"), no translation:
        the camera sweeps the walls round the robot (while the localization searches
        for it). The stuck clock holds and a back-off under way ends."""
        self._t = float(t)
        self.recovery.hold(float(t))
        self.recovery.stop()
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
        self.recovery.hold(float(t))
        obstacles = self.surroundings.remember(pose, obstacles, t)
        # Every near-field sight line counts: no map wall can be placed to explain one.
        lines = np.zeros((0, 4)) if near_lines is None else np.asarray(near_lines, dtype=np.float64).reshape(-1, 4)
        near = line_points(lines, self.avoid.near_field.point_step_m)
        if len(near):
            obstacles = np.vstack([obstacles, near])
        self.known = obstacles
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
        self.known = obstacles
        out = self._decide(pose, obstacles, t, located)
        out.near_points = len(near)
        return out

    def _decide(self, pose: np.ndarray, obstacles: np.ndarray, t: float, located: np.ndarray) -> NavCommand:
        """``located``: the obstacles whose place is known (not the near field's sight
        lines, which say only that something is closer than the camera sees): the lane
        shift goes round those; the near field makes the robot stop and look instead."""
        cfg, plan, rec = self.cfg, self.plan, self.recovery
        if plan.goal is None or len(plan.path) < 2:
            return NavCommand(np.zeros(3), "idle")
        xy = np.asarray(pose[:2], dtype=np.float64)
        goal_xy = plan.path[-1]
        to_goal = float(np.hypot(*(goal_xy - xy)))
        if to_goal < cfg.arrival_radius_m:
            return NavCommand(np.zeros(3), "arrived", carrot=goal_xy)
        backing = rec.look_back(pose, obstacles, t) if rec.looking_back else self._continue_backoff(pose, obstacles, t, located)
        if backing is not None:
            return backing
        s = plan.project(xy)
        if rec.stuck(s, t):
            return self._start_recovery(pose, obstacles, t, located)
        carrot = self.steering.carrot(plan, pose, s, located)
        d = carrot - xy
        desired = wrap_angle(math.atan2(d[1], d[0]) - float(pose[2]))
        turn = turn_rate(cfg, desired)
        if abs(desired) > cfg.turn_in_place_rad:
            return NavCommand(np.array([0.0, 0.0, turn]), "turning", carrot=carrot, desired_rad=desired)
        res = self.steering.choose_direction(pose, obstacles, desired, plan.lookahead(s) < cfg.lookahead_m)
        if res.blocked:
            # After blocked_wait_s without progress with the obstacle on the plan's line,
            # mark its edges blocked and re-plan; else back off or wait (Recovery.when_blocked).
            if self._replan_round_block(pose, located, t):
                carrot, desired, omega = self.steering.toward_plan(self.plan, pose)
                return NavCommand(np.array([0.0, 0.0, omega]), "blocked", carrot, desired, res.theta_star, res.open_length_m, (res.angles, res.lengths))
            return rec.when_blocked(pose, obstacles, t, carrot, desired, turn, res)
        speed = min(cfg.cruise_speed_mps, res.safe_speed_mps, 0.8 * to_goal + 0.05, plan.corner_speed_limit(s), plan.edge_speed_limit(s))
        return self.steering.drive(obstacles, carrot, desired, speed, res)

    def _continue_backoff(self, pose: np.ndarray, obstacles: np.ndarray, t: float, located: np.ndarray) -> NavCommand | None:
        """The back-off's command while it goes on (:meth:`Recovery.back_off`); None once
        it is over. A back-off from a blind block that goes on without progress re-plans
        round the block (:meth:`_replan_round_block`; ``located``: the obstacles whose
        place is known) and ends."""
        rec = self.recovery
        if not rec.backing_off(obstacles, t):
            return None
        if not rec.stuck_backoff and self._replan_round_block(pose, located, t):
            rec.end_backoff()
            carrot, desired, omega = self.steering.toward_plan(self.plan, pose)
            return NavCommand(np.array([0.0, 0.0, omega]), "turning", carrot, desired)
        return rec.back_off(self.plan, pose, obstacles, t)

    def _start_recovery(self, pose: np.ndarray, obstacles: np.ndarray, t: float, located: np.ndarray) -> NavCommand:
        """Recovery: mark the edges what blocks the robot stands on (``located``, the
        obstacles whose place is known; :meth:`RoutePlanner.mark_unless_put_off`),
        re-plan without them, and back off, turn towards the new plan or look back
        (:meth:`Recovery.start`)."""
        goal = self.plan.goal
        assert goal is not None
        self.replans += 1
        self.route.mark_unless_put_off(self.plan, pose, located, t, self.surroundings)
        self.set_goal(goal, pose, t + self.cfg.backoff_time_s)
        return self.recovery.start(self.plan, pose, obstacles, t)

    def _replan_round_block(self, pose: np.ndarray, located: np.ndarray, t: float) -> bool:
        """Blocked without progress for ``blocked_wait_s``: re-plan round the edges the
        obstacle stands on (:meth:`RoutePlanner.replan_round_block`). True when the plan
        goes round them; else the plan and the stuck clock stay as they were."""
        nodes = self.route.replan_round_block(self.plan, pose, located, t, self.recovery.progress_t, self.surroundings)
        if nodes is None:
            return False
        goal = self.plan.goal
        assert goal is not None
        self.replans += 1
        self.plan = self.route.plan(goal, nodes, pose)
        self.recovery.restart(t)
        return True
