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
    crosses_any,
    point_segment_distance,
    point_segment_projection,
    wrap_angle,
    wrap_angles,
)
from autonomy.maps.planner import NoPathError, astar, blind_lengths, edge_key, parts, path_points
from autonomy.maps.vectormap import NavGraph
from autonomy.navigation.avoidance import (
    AvoidanceConfig,
    AvoidanceResult,
    choose_direction,
    eq5_scores,
)
from autonomy.navigation.config import NavCommand, NavigatorConfig
from autonomy.navigation.surroundings import Surroundings
from autonomy.navigation.trail import Trail
from autonomy.perception.camera import KINECT_V1, DepthCamera
from autonomy.perception.nearfield import line_points

_LOOK_BACK_FACING_RAD = math.radians(10.0)
"""A look back drives once the robot faces the way back this closely."""
_BLOCKED_POINTS_KEPT = 64
"""At most this many of the points that blocked an edge are kept with its mark."""


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
        self._part = parts(graph, cfg.exclude_stairs)
        """The connected part of the graph each node (by index) lies in (:func:`autonomy.maps.planner.parts`)."""
        self.camera = camera
        self.walls = None if walls is None else np.asarray(walls, dtype=np.float64).reshape(-1, 4)
        self.surroundings = Surroundings(cfg, avoid, camera, self.walls)
        """The map's walls near the robot and the obstacle memory."""
        self._coastal: dict[tuple[int, int], float] = {}
        """Extra plan cost per edge for its blind metres (:attr:`NavigatorConfig.coastal_weight`)."""
        if self.walls is not None and cfg.coastal_weight > 0:
            blind = blind_lengths(graph, self.walls, cfg.coastal_range_m, 0.5 * camera.fov_h_rad)
            self._coastal = {k: cfg.coastal_weight * v for k, v in blind.items()}
        self.goal: int | None = None
        self.path = np.zeros((0, 2))
        self._cum = np.zeros(1)
        self._segments = np.zeros((0, 4))
        """The plan's segments (x1, y1, x2, y2) and their lengths (``_project``)."""
        self._seg_len = np.zeros(0)
        self._best_s = 0.0
        self._progress_t = 0.0
        self._backoff_until = -1.0
        self._backoff_started = -np.inf
        self._stuck_backoff = False
        self.replans = 0
        self.recoveries = 0
        self.blocked_edges = 0
        """Edges marked blocked so far (``blocked_edge_s``; a mark renewed is not counted)."""
        self.blocked: dict[tuple[int, int], float] = {}
        """The edges marked blocked now (node ids, the smaller first) and when each mark
        expires; the plans leave them out."""
        self._blocked_pts: dict[tuple[int, int], np.ndarray] = {}
        """World points of the obstacle that blocked each marked edge (the start of a
        re-plan is not taken through them)."""
        self.plan_nodes: list[int] = []
        """The plan's graph nodes (the plan runs from the pose to the first of them, then on)."""
        self._waited_since: float | None = None
        self._detour_from: float | None = None
        """When a long re-plan round a block was first put off (``long_detour_wait_s``)."""
        self._look_back: tuple[float, np.ndarray | None, float] | None = None
        """A look back under way (``look_back_m``): the heading to face, where the drive
        that way began (None while turning) and when it ends at the latest."""
        """The stuck clock's start when a blocked wait last re-planned to no avail."""
        self._t = 0.0
        """Time of the last frame (``command``)."""
        self.trail = Trail(cfg)
        """The robot's footprints (``trail_s``), along which a back-off goes."""
        self._side = 0
        self._lane = 0.0
        self._corners = np.zeros(0)
        self._seg_speed = np.zeros(0)
        self._narrow_s = np.zeros((0, 2))
        """The plan's narrow stretches (arc lengths from, to)."""
        self._edge_speed = {}
        self._edge_clearance: dict[tuple[int, int], float] = {}
        self._narrow_edges: dict[tuple[int, int], tuple[float, float]] = {}
        """Narrow edges (both ways round) and their narrow stretch (fractions along the
        edge from its first node), before and on which the carrot is ``narrow_lookahead_m``
        ahead."""
        xy = graph.node_xy()
        for e in graph.edges:
            if e.max_speed > 0:  # 0 in a map file: no limit given (a robot would never move)
                self._edge_speed[(e.s0_id, e.s1_id)] = float(e.max_speed)
                self._edge_speed[(e.s1_id, e.s0_id)] = float(e.max_speed)
            self._edge_clearance[(e.s0_id, e.s1_id)] = self._edge_clearance[(e.s1_id, e.s0_id)] = float(e.max_clearance)
            if e.has_door or e.max_clearance < avoid.robot_radius_m + cfg.narrow_slack_m:
                f0, f1 = self._narrow_stretch(xy[graph.index_of(e.s0_id)], xy[graph.index_of(e.s1_id)])
                self._narrow_edges[(e.s0_id, e.s1_id)] = (f0, f1)
                self._narrow_edges[(e.s1_id, e.s0_id)] = (1.0 - f1, 1.0 - f0)

    def _narrow_stretch(self, a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
        """The stretch of a narrow edge a-b (fractions from a) where the map's walls come
        within ``robot_radius_m + narrow_slack_m`` of it, or within 1 cm of its narrowest
        point when they come no closer (a wide door); the whole edge without walls."""
        L = float(np.hypot(*(b - a)))
        if self.walls is None or not len(self.walls) or L < 1e-6:
            return 0.0, 1.0
        lim = self.avoid.robot_radius_m + self.cfg.narrow_slack_m
        lo, hi = np.minimum(a, b) - lim - 1.0, np.maximum(a, b) + lim + 1.0
        w = self.walls
        near = (np.maximum(w[:, 0], w[:, 2]) >= lo[0]) & (np.minimum(w[:, 0], w[:, 2]) <= hi[0])
        near &= (np.maximum(w[:, 1], w[:, 3]) >= lo[1]) & (np.minimum(w[:, 1], w[:, 3]) <= hi[1])
        if not near.any():
            return 0.0, 1.0
        f = np.linspace(0.0, 1.0, max(2, int(math.ceil(L / 0.02)) + 1))
        c = point_segment_distance(a + f[:, None] * (b - a), w[near]).min(axis=1)
        on = f[c <= max(lim, float(c.min()) + 0.01)]
        return float(on.min()), float(on.max())

    # -- planning ----------------------------------------------------------------------
    def nearest_reachable_node(self, xy: np.ndarray, avoid: np.ndarray | None = None, goal_id: int | None = None) -> int:
        """The closest node that can be reached in a straight line (no wall in between).

        ``avoid``: world points (an obstacle that blocked an edge) the straight line must
        not run into (none within the avoidance radius of it, ahead); when every nearby
        node's line does, as if there were none. ``goal_id``: only the nodes with a path
        to that node count (a plan must go on from its first node)."""
        return self._nearest_in_reach(xy, avoid, goal_id)[0]

    def _nearest_in_reach(self, xy: np.ndarray, avoid: np.ndarray | None, goal_id: int | None) -> tuple[int, bool]:
        """:meth:`nearest_reachable_node`, and whether a straight line reaches it: of the
        30 nodes nearest ``xy`` (of the goal's part), the first no wall (nor ``avoid``)
        stands in front of; when every one has a wall in front, the nearest (False)."""
        nodes = self.graph.node_xy()
        order = np.argsort(np.hypot(nodes[:, 0] - xy[0], nodes[:, 1] - xy[1]))
        if goal_id is not None:
            order = order[self._part[order] == self._part[self.graph.index_of(goal_id)]]
        if avoid is not None and len(avoid):
            walls = self.walls if self.walls is not None and len(self.walls) else None
            for k in order[:30]:
                if (walls is None or not crosses_any(xy, nodes[k], walls)) and not self._line_runs_into(xy, nodes[k], avoid):
                    return int(self.graph.nodes[int(k)].id), True
        if self.walls is None or not len(self.walls):
            return int(self.graph.nodes[int(order[0])].id), True
        for k in order[:30]:
            if not crosses_any(xy, nodes[k], self.walls):
                return int(self.graph.nodes[int(k)].id), True
        return int(self.graph.nodes[int(order[0])].id), False

    def connected(self, a_id: int, b_id: int) -> bool:
        """Whether the graph has a path between two nodes (stairs as the plans take them)."""
        return bool(self._part[self.graph.index_of(a_id)] == self._part[self.graph.index_of(b_id)])

    def reaches(self, goal_ids, pose: np.ndarray) -> np.ndarray:
        """Which of the goals (node ids) a plan from the pose sets out to without going
        through a map wall: the nearest node in reach (:meth:`nearest_reachable_node`)
        has a path to the goal, or a node of the goal's part is in reach in a straight
        line. :meth:`set_goal` plans to the others too, from a node behind a wall: the
        best a robot can do when its belief is wrong, but no place to choose to go."""
        ids = np.atleast_1d(np.asarray(goal_ids, dtype=np.int64))
        xy = np.asarray(pose[:2], dtype=np.float64)
        part = self._part[[self.graph.index_of(int(g)) for g in ids]].reshape(-1)
        here = self._part[self.graph.index_of(self.nearest_reachable_node(xy))]
        ok = part == here
        for p in np.unique(part[~ok]):
            # One node of the part stands for all of it (the start depends on the part).
            g = int(ids[np.flatnonzero(part == p)[0]])
            ok[part == p] = self._nearest_in_reach(xy, None, g)[1]
        return ok

    def _line_runs_into(self, p: np.ndarray, q: np.ndarray, pts: np.ndarray) -> bool:
        """Whether a robot driving straight from ``p`` to ``q`` meets one of the points
        (ahead of ``p``, within the avoidance radius of the line, up to that radius past ``q``)."""
        r = self.avoid.radius_m
        u = np.asarray(q, dtype=np.float64) - p
        L = math.hypot(u[0], u[1])
        if L < 1e-9:
            return False
        u = u / L
        rel = pts - p
        along = rel @ u
        lateral = np.abs(rel[:, 1] * u[0] - rel[:, 0] * u[1])
        return bool(np.any((along > 0.0) & (along < L + r) & (lateral < r)))

    def set_goal(self, goal_id: int, pose: np.ndarray, t: float = 0.0) -> float:
        """Plan from the pose to a node; returns the plan's length in metres.

        The plan leaves out the edges marked blocked (``blocked``), and does not start
        through what blocked them; when that leaves no path, the marks are forgotten and
        the plan uses the whole graph. It starts at the nearest node in reach that has a
        path to the goal: a pose whose nearest node lies in a part of the graph cut off
        from the goal (a wrong belief, a robot carried off) is the robot's to recover
        from, so the plan is made from the nearest node that reaches the goal and this
        never fails for where the pose is (whether the goal is the user's mistake is for
        the caller to tell, from where the robot truly started: :meth:`reaches`)."""
        self._prune_blocked(t)
        nodes = self._route(goal_id, np.asarray(pose[:2]))
        if nodes is None:
            self.forget_blocked()
            nodes = self._route(goal_id, np.asarray(pose[:2]))
        assert nodes is not None
        self._set_plan(goal_id, nodes, pose, t)
        return float(self._cum[-1])

    def _route(self, goal_id: int, xy: np.ndarray) -> list[int] | None:
        """Graph nodes of a plan from ``xy`` to the goal without the blocked edges, not
        starting through what blocked them; None when the blocked edges leave no path.
        Without blocked edges there is always one: it starts in the goal's part of the
        graph (:meth:`nearest_reachable_node`)."""
        excluded = tuple(self.blocked)
        if not excluded:
            return astar(
                self.graph, self.nearest_reachable_node(xy, goal_id=goal_id), goal_id, exclude_stairs=self.cfg.exclude_stairs,
                extra=self._coastal,
            )
        avoid = np.vstack([self._blocked_pts.get(e, np.zeros((0, 2))) for e in excluded])
        try:
            start = self.nearest_reachable_node(xy, avoid, goal_id)
            return astar(self.graph, start, goal_id, exclude_stairs=self.cfg.exclude_stairs, excluded=excluded, extra=self._coastal)
        except NoPathError:
            return None

    def plan_points(self, goal_id: int, pose: np.ndarray) -> np.ndarray:
        """The polyline (K, 2) of the plan :meth:`set_goal` would make from the pose (the
        pose's position first), without making it."""
        xy = np.asarray(pose[:2], dtype=np.float64)
        nodes = self._route(goal_id, xy)
        if nodes is None:
            nodes = astar(
                self.graph, self.nearest_reachable_node(xy, goal_id=goal_id), goal_id, exclude_stairs=self.cfg.exclude_stairs,
                extra=self._coastal,
            )
        return np.vstack([xy[None, :], path_points(self.graph, nodes)])

    def plan_length(self, goal_id: int, pose: np.ndarray) -> float:
        """Length (m) of the plan :meth:`set_goal` would make from the pose, without
        making it (the stack asks while it relocalizes)."""
        pts = self.plan_points(goal_id, pose)
        return float(np.hypot(*np.diff(pts, axis=0).T).sum())

    def _set_plan(self, goal_id: int, nodes: list[int], pose: np.ndarray, t: float) -> None:
        """Make the path from the pose through ``nodes`` the plan (its segments, speed
        limits and corners) and start the stuck clock at ``t``."""
        self.plan_nodes = list(nodes)
        xy = np.asarray(pose[:2], dtype=np.float64)
        node_pts = path_points(self.graph, nodes)
        pairs: list[tuple[int, int] | None] = list(zip(nodes[:-1], nodes[1:], strict=True))
        if self._starts_on_first_edge(xy, nodes, node_pts):
            # The robot stands on the first edge, short of its first node (a waypoint
            # reached 0.3 m before it, the plan going back the way it came): the plan
            # runs from the pose along that edge, not forward to the node and back, where
            # a carrot on the doubled-back line jumps behind the robot.
            pts = np.vstack([xy[None, :], node_pts[1:]])
        else:
            # From the pose to the plan's first node: no edge (no speed limit, not narrow).
            pts = np.vstack([xy[None, :], node_pts])
            pairs = [None, *pairs]
        seg_len = np.hypot(*np.diff(pts, axis=0).T)
        keep = np.concatenate([[True], seg_len > 1e-6])
        self.path = pts[keep]
        kept = [ab for ab, k in zip(pairs, keep[1:], strict=True) if k]
        self._seg_speed = np.array([math.inf if ab is None else self._edge_speed.get(ab, math.inf) for ab in kept])
        seg = np.hypot(*np.diff(self.path, axis=0).T) if len(self.path) > 1 else np.zeros(0)
        self._cum = np.concatenate([[0.0], np.cumsum(seg)])
        self._segments = np.hstack([self.path[:-1], self.path[1:]])
        d = self._segments[:, 2:] - self._segments[:, :2]
        self._seg_len = np.sqrt(np.einsum("ij,ij->i", d, d))  # as _project's t measures them
        # Narrow stretches in arc length: each edge's stretch put on its segment (on the
        # first, which may start part way along its edge, a stretch behind the pose has
        # negative arc lengths: the robot's back may still be in it).
        spans = []
        all_xy = self.graph.node_xy()
        for k, ab in enumerate(kept):
            if ab is None or ab not in self._narrow_edges or self._seg_len[k] <= 0:
                continue
            f0, f1 = self._narrow_edges[ab]
            a, b = all_xy[self.graph.index_of(ab[0])], all_xy[self.graph.index_of(ab[1])]
            u = (self.path[k + 1] - self.path[k]) / self._seg_len[k]
            spans.append([self._cum[k] + float((a + f * (b - a) - self.path[k]) @ u) for f in (f0, f1)])
        self._narrow_s = np.array(spans, dtype=np.float64).reshape(-1, 2)
        # Corners: inner vertices where the plan turns by more than corner_angle_rad.
        self._corners = np.zeros(0)
        if len(self.path) > 2:
            d = np.diff(self.path, axis=0)
            heading = np.arctan2(d[:, 1], d[:, 0])
            turn = np.abs(wrap_angles(np.diff(heading)))
            self._corners = self._cum[1:-1][turn > self.cfg.corner_angle_rad]
        self.goal = goal_id
        self._best_s = 0.0
        self._progress_t = t

    def _starts_on_first_edge(self, xy: np.ndarray, nodes: list[int], node_pts: np.ndarray) -> bool:
        """Whether ``xy`` lies part way along the plan's first edge (projecting inside it,
        within its ``max_clearance``) with a straight way free of walls to its second node."""
        if len(nodes) < 2:
            return False
        a, b = node_pts[0], node_pts[1]
        t, dist = point_segment_projection(xy, np.array([[*a, *b]]))
        if not (0.0 < t[0] < 1.0) or dist[0] > self._edge_clearance.get((nodes[0], nodes[1]), 0.0):
            return False
        return self.walls is None or not len(self.walls) or not crosses_any(xy, b, self.walls)

    def remaining_m(self, pose: np.ndarray) -> float:
        """Length of the plan still ahead of the pose (from the plan's point nearest it);
        0 without a plan."""
        if len(self.path) < 2:
            return 0.0
        return float(self._cum[-1]) - self._project(np.asarray(pose[:2], dtype=np.float64))

    def _project(self, xy: np.ndarray) -> float:
        """Arc length of the point of the plan nearest ``xy``."""
        t, dist = point_segment_projection(xy, self._segments)
        k = int(np.argmin(dist))
        return float(self._cum[k] + t[k] * self._seg_len[k])

    def corner_speed_limit(self, s: float) -> float:
        """Speed limit at arc length ``s`` of the plan from its corners: ``corner_speed_mps``
        from ``corner_before_m`` before a corner to ``corner_after_m`` past it, rising
        linearly to the cruise speed over ``corner_ramp_m`` before that; inf when off."""
        cfg = self.cfg
        if cfg.corner_speed_mps <= 0 or not len(self._corners):
            return math.inf
        ahead = self._corners - s
        ahead = ahead[ahead >= -cfg.corner_after_m]
        if not len(ahead):
            return math.inf
        d = float(ahead.min()) - cfg.corner_before_m
        if d <= 0.0:
            return cfg.corner_speed_mps
        if cfg.corner_ramp_m <= 0 or d >= cfg.corner_ramp_m:
            return math.inf
        return cfg.corner_speed_mps + (cfg.cruise_speed_mps - cfg.corner_speed_mps) * d / cfg.corner_ramp_m

    def edge_speed_limit(self, s: float) -> float:
        """The lowest ``max_speed`` of the plan's edges from ``robot_radius_m`` behind arc
        length ``s`` to ``lookahead_m`` ahead of it; inf when off or unlimited."""
        if not self.cfg.edge_speed_limits or not len(self._seg_speed):
            return math.inf
        lo, hi = s - self.avoid.robot_radius_m, s + self.cfg.lookahead_m
        on = (self._cum[1:] > lo) & (self._cum[:-1] < hi)
        return float(self._seg_speed[on].min()) if on.any() else math.inf

    def lookahead(self, s: float) -> float:
        """Carrot distance at arc length ``s``: ``narrow_lookahead_m`` from
        ``narrow_before_m`` before a narrow stretch of the plan until ``robot_radius_m``
        past it, else ``lookahead_m``."""
        cfg = self.cfg
        if cfg.narrow_lookahead_m <= 0 or not len(self._narrow_s):
            return cfg.lookahead_m
        lo, hi = s - self.avoid.robot_radius_m, s + cfg.narrow_before_m
        on = (self._narrow_s[:, 1] >= lo) & (self._narrow_s[:, 0] <= hi)
        return cfg.narrow_lookahead_m if on.any() else cfg.lookahead_m

    def obstacle_near_path(self, obstacles: np.ndarray, theta: float) -> bool:
        """Whether an obstacle point lies less than ``proximity_range_m`` ahead along
        ``theta`` and within the avoidance radius plus ``proximity_gap_m`` of that ray."""
        o = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
        if not len(o):
            return False
        c, s = math.cos(theta), math.sin(theta)
        along = o[:, 0] * c + o[:, 1] * s
        lateral = np.abs(o[:, 1] * c - o[:, 0] * s)
        near = (along > 0.0) & (along < self.cfg.proximity_range_m) & (lateral < self.avoid.radius_m + self.cfg.proximity_gap_m)
        return bool(near.any())

    def _point_at(self, s: float) -> np.ndarray:
        s = min(max(s, 0.0), float(self._cum[-1]))
        k = min(max(int(np.searchsorted(self._cum, s, side="right")) - 1, 0), len(self.path) - 2)
        L = self._cum[k + 1] - self._cum[k]
        a = 0.0 if L == 0 else (s - self._cum[k]) / L
        return self.path[k] + a * (self.path[k + 1] - self.path[k])

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

    def _plan_direction(self, pose: np.ndarray) -> tuple[np.ndarray, float, float]:
        """The carrot on the plan (no lane shift), its direction in the robot frame and
        the yaw rate turning towards it."""
        cfg = self.cfg
        xy = np.asarray(pose[:2], dtype=np.float64)
        if len(self.path) < 2:
            return xy, 0.0, 0.0
        s = self._project(xy)
        carrot = self._point_at(s + self.lookahead(s))
        d = carrot - xy
        desired = wrap_angle(math.atan2(d[1], d[0]) - float(pose[2]))
        return carrot, desired, float(np.clip(cfg.heading_gain * desired, -cfg.max_turn_rate_rad_s, cfg.max_turn_rate_rad_s))

    def _turn_to_plan(self, pose: np.ndarray) -> np.ndarray:
        """Turning in place towards the plan (a round robot can always turn)."""
        return np.array([0.0, 0.0, self._plan_direction(pose)[2]])

    def _prune_blocked(self, t: float) -> None:
        """Forget the marks that expired by ``t``."""
        for e in [e for e, until in self.blocked.items() if until <= t]:
            del self.blocked[e]
            self._blocked_pts.pop(e, None)

    def forget_blocked(self) -> None:
        """Forget every blocked edge (the next plan uses the whole graph)."""
        self.blocked.clear()
        self._blocked_pts.clear()

    def blocking_points(self, pose: np.ndarray, located: np.ndarray) -> np.ndarray:
        """The ``located`` obstacles (robot frame) on the plan's line ahead, in the world
        frame (through the pose): within the avoidance radius of the plan between that
        radius behind the robot's place on it and ``blocked_check_m`` ahead, and not
        explained by a map wall (none within ``near_wall_tol_m``)."""
        cfg, r = self.cfg, self.avoid.radius_m
        obs = np.asarray(located, dtype=np.float64).reshape(-1, 2)
        if not len(obs) or not len(self._segments):
            return np.zeros((0, 2))
        xy = np.asarray(pose[:2], dtype=np.float64)
        c, sn = math.cos(float(pose[2])), math.sin(float(pose[2]))
        rel = np.column_stack([c * obs[:, 0] - sn * obs[:, 1], sn * obs[:, 0] + c * obs[:, 1]])  # world axes
        w = rel + xy
        # The stretch checked: each plan segment cut to arc lengths [s0 - r, s0 + check].
        s0 = self._project(xy)
        lo, hi = s0 - r, s0 + cfg.blocked_check_m
        seg = np.flatnonzero((self._cum[1:] > lo) & (self._cum[:-1] < hi))
        a, d = self._segments[seg, :2], self._segments[seg, 2:] - self._segments[seg, :2]
        L = np.maximum(self._seg_len[seg], 1e-12)
        f0 = (np.clip(lo - self._cum[seg], 0.0, None) / L)[:, None]
        f1 = (np.clip(hi - self._cum[seg], None, self._seg_len[seg]) / L)[:, None]
        on = (point_segment_distance(w, np.hstack([a + f0 * d, a + f1 * d])) < r).any(axis=1)
        rel, w = rel[on], w[on]
        if len(rel):
            walls = self.surroundings.near_walls(pose, float(np.max(np.hypot(rel[:, 0], rel[:, 1]))) + cfg.near_wall_tol_m)
            if len(walls):
                d2 = ((rel[:, None, :] - walls[None, :, :]) ** 2).sum(axis=-1).min(axis=1)
                w = w[d2 >= cfg.near_wall_tol_m**2]
        return w

    def _mark_blocked(self, pose: np.ndarray, located: np.ndarray, t: float) -> bool:
        """Mark blocked (until ``t + blocked_edge_s``) the graph edges within the avoidance
        radius of the obstacle on the plan's line ahead (:meth:`blocking_points`): the
        plan's edges and those of its first node (the robot may stand on one of them,
        short of that node). True when an edge was not marked before."""
        cfg = self.cfg
        if cfg.blocked_edge_s <= 0 or not self.plan_nodes:
            return False
        pts = self.blocking_points(pose, located)
        if not len(pts):
            return False
        first = self.plan_nodes[0]
        cand = {edge_key(a, b) for a, b in zip(self.plan_nodes[:-1], self.plan_nodes[1:], strict=True)}
        cand |= {edge_key(e.s0_id, e.s1_id) for e in self.graph.edges if first in (e.s0_id, e.s1_id)}
        edges = sorted(cand)
        if not edges:
            return False
        nodes = self.graph.node_xy()
        segs = np.array([[*nodes[self.graph.index_of(a)], *nodes[self.graph.index_of(b)]] for a, b in edges], dtype=np.float64)
        near = point_segment_distance(pts, segs) < self.avoid.radius_m  # (points, edges)
        new = False
        for j in np.flatnonzero(near.any(axis=0)):
            e = edges[int(j)]
            if e not in self.blocked:
                new = True
                self.blocked_edges += 1
            self.blocked[e] = t + cfg.blocked_edge_s
            on = pts[near[:, j]]
            self._blocked_pts[e] = on[:: max(1, int(math.ceil(len(on) / _BLOCKED_POINTS_KEPT)))]
        return new

    def _marks(self) -> tuple[dict, dict, int]:
        """The blocked edges' marks, to restore (:meth:`_restore_marks`)."""
        return dict(self.blocked), dict(self._blocked_pts), self.blocked_edges

    def _restore_marks(self, marks: tuple[dict, dict, int]) -> None:
        self.blocked, self._blocked_pts, self.blocked_edges = dict(marks[0]), dict(marks[1]), marks[2]

    def _detour_put_off(self, t: float) -> bool:
        """Whether a long re-plan round a block is being put off at ``t``."""
        w = self.cfg.long_detour_wait_s
        return self._detour_from is not None and t - self._detour_from < w

    def _put_off_detour(self, pose: np.ndarray, nodes: list[int] | None, t: float) -> bool:
        """Whether to put off, for now, the re-plan ``nodes`` round the edges marked
        blocked (:meth:`_route` with the marks): it is longer than what is left of the
        plan by more than ``long_detour_m`` and the block has held less than
        ``long_detour_wait_s`` since such a re-plan was first put off (a first put-off
        more than three waits ago is forgotten: a new block)."""
        cfg = self.cfg
        if cfg.long_detour_wait_s <= 0 or self.goal is None or len(self.path) < 2:
            return False
        xy = np.asarray(pose[:2], dtype=np.float64)
        if nodes is None or nodes == self.plan_nodes:
            return False
        pts = np.vstack([xy[None, :], path_points(self.graph, nodes)])
        detour = float(np.hypot(*np.diff(pts, axis=0).T).sum())
        if detour <= float(self._cum[-1]) - self._project(xy) + cfg.long_detour_m:
            return False
        if self._detour_from is None or t - self._detour_from > 3.0 * cfg.long_detour_wait_s:
            self._detour_from = t
        return t - self._detour_from < cfg.long_detour_wait_s

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
        turn = float(np.clip(cfg.heading_gain * desired, -cfg.max_turn_rate_rad_s, cfg.max_turn_rate_rad_s))
        if abs(desired) > cfg.turn_in_place_rad:
            return NavCommand(np.array([0.0, 0.0, turn]), "turning", carrot=carrot, desired_rad=desired)
        static = np.zeros((0, 2))
        if seen is not None and cfg.map_blind_spots_m > 0:
            static = np.asarray(seen, dtype=np.float64).reshape(-1, 2)
            static = self.surroundings.out_of_view(static[static[:, 0] ** 2 + static[:, 1] ** 2 < cfg.map_blind_spots_m**2])
        res = self._keep_side(
            choose_direction(obstacles, desired, self.avoid, static, self.avoid.robot_radius_m + cfg.map_clearance_m), desired
        )
        if res.blocked:
            return NavCommand(np.array([0.0, 0.0, turn]), "blocked", carrot, desired, res.theta_star, res.open_length_m, (res.angles, res.lengths))
        return self._drive(obstacles, carrot, desired, min(cfg.cruise_speed_mps, res.safe_speed_mps), res)

    def pose_jumped(self, pose: np.ndarray | None = None, t: float | None = None) -> None:
        """The pose estimate jumped (the robot was re-localized elsewhere): forget what
        was placed through the old estimate -- the obstacle memory, the trail, the lane
        and side chosen -- and a back-off under way; given the new ``pose`` and with a
        goal set, re-plan from it (at ``t``, default the last frame's time). Blocked
        edges stay marked (they expire, and are forgotten when they leave no path)."""
        self.surroundings.forget()
        self.trail.clear()
        self._lane = 0.0
        self._side = 0
        self._backoff_until = -1.0
        self._backoff_started = -np.inf
        self._stuck_backoff = False
        self._look_back = None
        if pose is not None and self.goal is not None:
            self.replans += 1
            self.set_goal(self.goal, pose, self._t if t is None else float(t))

    def lane_offset(self, pose: np.ndarray, obstacles: np.ndarray, s: float) -> float:
        """Sideways shift (m, left of the plan positive) of the carrot (``lane_shift_m``).

        In the plan's frame at arc length ``s`` (its tangent, over the straight stretch
        ahead, at most ``lane_check_m`` and up to the next corner), an offset o is clear
        when no obstacle ahead (from the avoidance radius behind ``s`` on) lies within
        the avoidance radius of the line at o, nor a map wall within the robot radius
        plus ``map_clearance_m``. 0 when the plan's own line is clear (Eq. 5 as the paper)
        or no offset is; else the clear offset nearest 0, on the side chosen before while
        that side has one; the first choice is the side of the clear offset nearest the
        robot (on a tie the right).
        """
        shift = 0.0
        frame = self._lane_frame(s) if self.cfg.lane_shift_m > 0 and len(self.path) >= 2 else None
        if frame is not None:
            lats = self._lane_laterals(pose, obstacles, frame)
            # Most frames end here: the plan's own line is clear.
            if any(bool(np.any(np.abs(lat) < gap)) for lat, gap in lats):
                shift = self._pick_lane(pose, frame, lats)
        self._lane = float(np.sign(shift))
        return shift

    def _lane_frame(self, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
        """The plan's frame for :meth:`lane_offset` at arc length ``s``: its point, unit
        tangent and left normal there, and how far ahead the stretch is checked
        (``lane_check_m``, up to the next corner and the plan's end); None when that is
        shorter than the avoidance radius or the plan has no direction there."""
        reach = self.cfg.lane_check_m
        ahead = self._corners - s
        ahead = ahead[ahead > 0.0]
        if len(ahead):
            reach = min(reach, float(ahead.min()))
        reach = min(reach, float(self._cum[-1]) - s)
        if reach < self.avoid.radius_m:
            return None
        p0 = self._point_at(s)
        u = self._point_at(s + min(reach, 0.5)) - p0 if reach > 1e-6 else np.zeros(2)
        nu = math.hypot(u[0], u[1])
        if nu < 1e-9:
            return None
        u = u / nu
        return p0, u, np.array([-u[1], u[0]]), reach

    def _lane_laterals(
        self, pose: np.ndarray, obstacles: np.ndarray, frame: tuple[np.ndarray, np.ndarray, np.ndarray, float]
    ) -> list[tuple[np.ndarray, float]]:
        """Lateral offsets (plan frame) of the obstacles and of the map's walls on the
        stretch ahead (from the avoidance radius behind its start to ``reach``), each with
        the gap it needs: the avoidance radius for sensed points, the robot radius plus
        ``map_clearance_m`` for walls."""
        cfg, r = self.cfg, self.avoid.radius_m
        p0, u, n, reach = frame
        c, sn = math.cos(float(pose[2])), math.sin(float(pose[2]))
        rel0 = np.asarray(pose[:2], dtype=np.float64) - p0
        # Plan-frame axes of robot-frame points (sensed) and of world-axes offsets (walls).
        ua, na = (c * u[0] + sn * u[1], -sn * u[0] + c * u[1]), (c * n[0] + sn * n[1], -sn * n[0] + c * n[1])
        a0, l0 = float(rel0 @ u), float(rel0 @ n)
        obs = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
        walls = self.surroundings.near_walls(pose, reach + cfg.lane_shift_m + r)
        lats = []
        for pts, (au, nu_), gap in (
            (obs, (ua, na), r),
            (walls, (u, n), self.avoid.robot_radius_m + cfg.map_clearance_m),
        ):
            if len(pts):
                a = pts[:, 0] * au[0] + pts[:, 1] * au[1] + a0
                lat = pts[:, 0] * nu_[0] + pts[:, 1] * nu_[1] + l0
                lats.append((lat[(a > -r) & (a < reach)], gap))
        return lats

    def _pick_lane(
        self, pose: np.ndarray, frame: tuple[np.ndarray, np.ndarray, np.ndarray, float], lats: list[tuple[np.ndarray, float]]
    ) -> float:
        """The clear offset nearest the plan, on the side chosen before while that side
        has one (0 when none is clear); the first choice is the side of the clear offset
        nearest the robot."""
        cfg = self.cfg
        p0, _, n, _ = frame
        k = int(math.floor(cfg.lane_shift_m / _LANE_STEP_M + 1e-9))
        offsets = _LANE_STEP_M * np.arange(-k, k + 1)
        clear = np.ones(len(offsets), dtype=bool)
        for lat, gap in lats:
            lat = lat[np.abs(lat) < cfg.lane_shift_m + gap]
            if len(lat):
                clear &= ~(np.abs(lat[:, None] - offsets[None, :]) < gap).any(axis=0)
        if not clear.any():
            return 0.0
        side = self._lane
        if side == 0.0:
            # First choice: the clear offset nearest the robot (a tie: the right, since
            # people step to their right, the robot's left, out of its way).
            lat = float((np.asarray(pose[:2], dtype=np.float64) - p0) @ n)
            cost = np.where(clear, np.abs(offsets - lat) + 1e-9 * (offsets > 0), np.inf)
            side = 1.0 if offsets[int(np.argmin(cost))] > 0 else -1.0
        same = clear & (np.sign(offsets) == side)
        pick = same if same.any() else clear
        j = int(np.flatnonzero(pick)[np.argmin(np.abs(offsets[pick]))])
        return float(offsets[j])

    def _keep_side(self, res: AvoidanceResult, desired: float, horizon: float | None = None) -> AvoidanceResult:
        """Hysteresis on Eq. 5: once the robot swerves to one side of the carrot direction,
        it keeps to that side while a direction there scores at least ``side_hysteresis``
        of the best (flipping left-right-left in front of an obstacle wastes the approach)."""
        cfg = self.cfg
        band = math.radians(3.0)
        side = _side_of(res.theta_star, desired, band)
        prev = self._side
        if prev != 0 and side == -prev and not res.blocked:
            score = eq5_scores(res.angles, res.lengths, desired, horizon)
            same = np.array([_side_of(a, desired, band) != -prev for a in res.angles])
            if same.any():
                j = int(np.flatnonzero(same)[np.argmax(score[same])])
                if score[j] >= cfg.side_hysteresis * float(score.max()) and res.lengths[j] > self.avoid.stop_distance_m:
                    d = float(res.lengths[j])
                    v = math.sqrt(2.0 * self.avoid.max_decel_mps2 * max(0.0, d - self.avoid.stop_distance_m))
                    res = AvoidanceResult(res.angles, res.lengths, j, float(res.angles[j]), d, v, False)
                    side = prev
        self._side = side
        return res

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
        if self.blocked:
            self._prune_blocked(t)
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
        if self.goal is None or len(self.path) < 2:
            return NavCommand(np.zeros(3), "idle")
        xy = np.asarray(pose[:2], dtype=np.float64)
        goal_xy = self.path[-1]
        to_goal = float(np.hypot(*(goal_xy - xy)))
        if to_goal < cfg.arrival_radius_m:
            return NavCommand(np.zeros(3), "arrived", carrot=goal_xy)
        if self._look_back is not None:
            backing = self._continue_look_back(pose, obstacles, t)
        else:
            backing = self._continue_backoff(pose, obstacles, t, obstacles if located is None else located)
        if backing is not None:
            return backing
        s = self._project(xy)
        if self._stuck(s, t):
            return self._start_recovery(pose, obstacles, t, located)
        carrot = self._carrot(pose, s, obstacles if located is None else located)
        d = carrot - xy
        desired = wrap_angle(math.atan2(d[1], d[0]) - float(pose[2]))
        turn = float(np.clip(cfg.heading_gain * desired, -cfg.max_turn_rate_rad_s, cfg.max_turn_rate_rad_s))
        if abs(desired) > cfg.turn_in_place_rad:
            return NavCommand(np.array([0.0, 0.0, turn]), "turning", carrot=carrot, desired_rad=desired)
        res = self._choose_direction(pose, obstacles, desired, self.lookahead(s) < cfg.lookahead_m)
        if res.blocked:
            return self._when_blocked(pose, obstacles, t, carrot, desired, turn, res, located)
        speed = min(cfg.cruise_speed_mps, res.safe_speed_mps, 0.8 * to_goal + 0.05, self.corner_speed_limit(s), self.edge_speed_limit(s))
        return self._drive(obstacles, carrot, desired, speed, res)

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
            carrot, desired, omega = self._plan_direction(pose)
            return NavCommand(np.array([0.0, 0.0, omega]), "turning", carrot, desired)
        v = self._backoff_velocity(pose, obstacles)
        if self._stuck_backoff:
            self._progress_t = t
        if v.any():
            return NavCommand(v, "recovering")
        if t < self._backoff_until:
            return NavCommand(self._turn_to_plan(pose), "recovering")
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
        marks = self._marks()
        self._mark_blocked(pose, obstacles if located is None else located, t)
        if self._put_off_detour(pose, self._route(self.goal, np.asarray(pose[:2])), t):
            self._restore_marks(marks)
        self.set_goal(self.goal, pose, t + cfg.backoff_time_s)
        v = self._backoff_velocity(pose, obstacles)
        if v.any():
            return NavCommand(v, "recovering")
        _, desired, omega = self._plan_direction(pose)
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
                return NavCommand(np.array([0.0, 0.0, float(np.clip(cfg.heading_gain * err, -cfg.max_turn_rate_rad_s, cfg.max_turn_rate_rad_s))]), "recovering")
            self._look_back = (heading, xy.copy(), until)
        res = self._choose_direction(pose, obstacles, err)
        if res.blocked:
            self._look_back = None
            return None
        th = res.theta_star
        omega = float(np.clip(cfg.heading_gain * th, -cfg.max_turn_rate_rad_s, cfg.max_turn_rate_rad_s))
        fan = (res.angles, res.lengths)
        if abs(th) > 0.5 * self.camera.fov_h_rad:
            return NavCommand(np.array([0.0, 0.0, omega]), "recovering", theta_star_rad=th, open_length_m=res.open_length_m, fan=fan)
        speed = min(cfg.backoff_speed_mps, res.safe_speed_mps)
        v = np.array([speed * math.cos(th), speed * math.sin(th), omega])
        return NavCommand(v, "recovering", theta_star_rad=th, open_length_m=res.open_length_m, fan=fan)

    def _carrot(self, pose: np.ndarray, s: float, located: np.ndarray) -> np.ndarray:
        """The carrot: :meth:`lookahead` ahead of arc length ``s`` on the plan, shifted
        sideways round the ``located`` obstacles by :meth:`lane_offset`."""
        la = self.lookahead(s)
        carrot = self._point_at(s + la)
        shift = self.lane_offset(pose, located, s)
        if shift:
            t0 = self._point_at(s + la + 0.05) - self._point_at(s + la - 0.05)
            t0 = t0 / max(1e-9, math.hypot(t0[0], t0[1]))
            carrot = carrot + shift * np.array([-t0[1], t0[0]])
        return carrot

    def _choose_direction(self, pose: np.ndarray, obstacles: np.ndarray, desired: float, short: bool = False) -> AvoidanceResult:
        """Eq. 3-5 on the obstacles and the map's walls in the camera's blind spots,
        with hysteresis on the side (:meth:`_keep_side`); ``short``: the carrot is short
        (``narrow_horizon_m``)."""
        static = self.surroundings.map_blind_spots(pose)
        horizon = self.cfg.narrow_horizon_m if short and self.cfg.narrow_horizon_m > 0 else None
        res = choose_direction(
            np.asarray(obstacles, dtype=np.float64).reshape(-1, 2),
            desired,
            self.avoid,
            static,
            self.avoid.robot_radius_m + self.cfg.map_clearance_m,
            horizon,
        )
        return self._keep_side(res, desired, horizon)

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
            carrot, desired, omega = self._plan_direction(pose)
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
        """Blocked (Eq. 5 finds no open direction, or a back-off from what blocks is under
        way) without progress for ``blocked_wait_s``: mark the edges the obstacle stands
        on (:meth:`_mark_blocked`) and re-plan. True when the plan goes round them; when
        it does not (no other way: the marks were forgotten, or they are off the plan),
        the robot waits as before, the stuck clock running on, and tries again only after
        some progress."""
        cfg = self.cfg
        if not (
            cfg.blocked_edge_s > 0
            and self.goal is not None
            and t - self._progress_t >= cfg.blocked_wait_s
            and self._progress_t != self._waited_since
            and not self._detour_put_off(t)
        ):
            return False
        marks = self._marks()
        if not self._mark_blocked(pose, located, t):
            return False
        nodes = self._route(self.goal, np.asarray(pose[:2]))
        if self._put_off_detour(pose, nodes, t):
            self._restore_marks(marks)
            return False
        if nodes is None or nodes == self.plan_nodes:
            # No other way: the plan and the stuck clock stay as they were.
            if nodes is None:
                self.forget_blocked()
            self._waited_since = self._progress_t
            return False
        self.replans += 1
        self._set_plan(self.goal, nodes, pose, t)
        return True

    def _drive(self, obstacles: np.ndarray, carrot: np.ndarray, desired: float, speed: float, res: AvoidanceResult) -> NavCommand:
        """Drive along theta* at ``speed``, turning towards it (look where the robot goes);
        only turn while theta* lies outside the camera's view (``look_first``), and slow
        down near obstacles (``proximity_speed_mps``)."""
        cfg = self.cfg
        fan = (res.angles, res.lengths)
        th = res.theta_star
        omega = float(np.clip(cfg.heading_gain * th, -cfg.max_turn_rate_rad_s, cfg.max_turn_rate_rad_s))
        if abs(th) > 0.5 * self.camera.fov_h_rad:
            if cfg.look_first:
                return NavCommand(np.array([0.0, 0.0, omega]), "turning", carrot, desired, th, res.open_length_m, fan)
            if cfg.unseen_speed_mps > 0:
                speed = min(speed, cfg.unseen_speed_mps)
        if cfg.proximity_speed_mps > 0 and self.obstacle_near_path(obstacles, th):
            speed = min(speed, cfg.proximity_speed_mps)
        v = np.array([speed * math.cos(th), speed * math.sin(th), omega])
        return NavCommand(v, "driving", carrot, desired, th, res.open_length_m, fan)

_LANE_STEP_M = 0.05
"""Spacing of the carrot shifts tried (``Navigator.lane_offset``)."""


def _side_of(theta: float, desired: float, dead_band: float) -> int:
    d = wrap_angle(theta - desired)
    return 0 if abs(d) <= dead_band else (1 if d > 0 else -1)

