"""Plans on the navigation graph and the edges marked blocked.

A plan is A* (:mod:`autonomy.maps.planner`, coastal costs) from the nearest node in
reach of the pose to the goal, leaving out stairs and the edges marked blocked: a box or
a closed door across a corridor is not in the map, so a re-plan on the same graph would
lead back into it (``blocked_edge_s``). :class:`RoutePlanner` makes the
:class:`~autonomy.navigation.plan.Plan` the navigator follows, and keeps the marks.
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import (
    crosses_any,
    point_segment_distance,
    point_segment_projection,
)
from autonomy.maps.navgraph import NavGraph
from autonomy.maps.planner import (
    BlindSegments,
    NoPathError,
    astar,
    blind_lengths,
    edge_key,
    parts,
    path_points,
)
from autonomy.navigation.avoidance import AvoidanceConfig
from autonomy.navigation.config import NavigatorConfig
from autonomy.navigation.plan import Plan
from autonomy.navigation.shortcut import Shortcuts
from autonomy.navigation.surroundings import Surroundings
from autonomy.perception.camera import DepthCamera

_BLOCKED_POINTS_KEPT = 64
"""At most this many of the points that blocked an edge are kept with its mark."""

Marks = tuple[dict, dict, int]
"""A copy of the blocked edges' marks (:meth:`RoutePlanner._marks`)."""


class RoutePlanner:
    """Plans to graph nodes round the edges marked blocked.

    ``walls``: the map's wall segments (K, 4), world frame, or None; ``camera``: its
    field of view decides which metres of an edge are blind (``coastal_weight``).
    """

    def __init__(
        self, graph: NavGraph, cfg: NavigatorConfig, avoid: AvoidanceConfig, walls: np.ndarray | None, camera: DepthCamera
    ) -> None:
        self.graph = graph
        self.cfg = cfg
        self.avoid = avoid
        self.walls = walls
        self._part = parts(graph, cfg.exclude_stairs)
        """The connected part of the graph each node (by index) lies in (:func:`autonomy.maps.planner.parts`)."""
        self._coastal: dict[tuple[int, int], float] = {}
        """Extra plan cost per edge for its blind metres (:attr:`NavigatorConfig.coastal_weight`)."""
        blind_segments = None
        if self.walls is not None and cfg.coastal_weight > 0:
            blind_segments = BlindSegments(self.walls, cfg.coastal_range_m, 0.5 * camera.fov_h_rad)
            blind = blind_lengths(graph, self.walls, cfg.coastal_range_m, 0.5 * camera.fov_h_rad)
            self._coastal = {k: cfg.coastal_weight * v for k, v in blind.items()}
        self._shortcuts = None
        """Straightens plans (:attr:`NavigatorConfig.shortcut_clearance_m`; None: off or no walls known)."""
        if self.walls is not None and cfg.shortcut_clearance_m > 0:
            self._shortcuts = Shortcuts(self.walls, cfg.shortcut_clearance_m, cfg.shortcut_blind_slack_m, blind_segments)
        self.blocked_edges = 0
        """Edges marked blocked so far (``blocked_edge_s``; a mark renewed is not counted)."""
        self.blocked: dict[tuple[int, int], float] = {}
        """The edges marked blocked now (node ids, the smaller first) and when each mark
        expires; the plans leave them out."""
        self._blocked_pts: dict[tuple[int, int], np.ndarray] = {}
        """World points of the obstacle that blocked each marked edge (the start of a
        re-plan is not taken through them)."""
        self._waited_since: float | None = None
        """The stuck clock's start when a blocked wait last re-planned to no avail."""
        self._detour_from: float | None = None
        """When a long re-plan round a block was first put off (``long_detour_wait_s``)."""
        self._edge_speed = {}
        self._edge_clearance: dict[tuple[int, int], float] = {}
        self._narrow_edges: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        """Narrow edges (both ways round) and the ends of their narrow stretch (world
        points, from the edge's first node on), before and on which the carrot is
        ``narrow_lookahead_m`` ahead."""
        xy = graph.node_xy()
        for e in graph.edges:
            if e.max_speed > 0:  # 0 in a map file: no limit given (a robot would never move)
                self._edge_speed[(e.s0_id, e.s1_id)] = float(e.max_speed)
                self._edge_speed[(e.s1_id, e.s0_id)] = float(e.max_speed)
            self._edge_clearance[(e.s0_id, e.s1_id)] = self._edge_clearance[(e.s1_id, e.s0_id)] = float(e.max_clearance)
            if e.has_door or e.max_clearance < avoid.robot_radius_m + cfg.narrow_slack_m:
                a, b = xy[graph.index_of(e.s0_id)], xy[graph.index_of(e.s1_id)]
                f0, f1 = self._narrow_stretch(a, b)
                self._narrow_edges[(e.s0_id, e.s1_id)] = (a + f0 * (b - a), a + f1 * (b - a))
                self._narrow_edges[(e.s1_id, e.s0_id)] = (b + (1.0 - f1) * (a - b), b + (1.0 - f0) * (a - b))

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

    # -- where a plan starts ------------------------------------------------------------
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
        line. :meth:`plan_to` plans to the others too, from a node behind a wall: the
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

    # -- plans --------------------------------------------------------------------------
    def plan_to(self, goal_id: int, pose: np.ndarray, t: float) -> Plan:
        """The plan from the pose to a node at ``t``.

        It leaves out the edges marked blocked (``blocked``), and does not start through
        what blocked them; when that leaves no path, the marks are forgotten and the plan
        uses the whole graph. It starts at the nearest node in reach that has a path to
        the goal: a pose whose nearest node lies in a part of the graph cut off from the
        goal (a wrong belief, a robot carried off) is the robot's to recover from, so the
        plan is made from the nearest node that reaches the goal and this never fails for
        where the pose is (whether the goal is the user's mistake is for the caller to
        tell, from where the robot truly started: :meth:`reaches`)."""
        self.prune_blocked(t)
        nodes = self.route(goal_id, np.asarray(pose[:2]))
        if nodes is None:
            self.forget_blocked()
            nodes = self.route(goal_id, np.asarray(pose[:2]))
        assert nodes is not None
        return self.plan(goal_id, nodes, pose)

    def route(self, goal_id: int, xy: np.ndarray) -> list[int] | None:
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
        """The polyline (K, 2) of the plan :meth:`plan_to` would make from the pose (the
        pose's position first, straightened as the robot would drive it), without
        making it or forgetting any mark."""
        xy = np.asarray(pose[:2], dtype=np.float64)
        nodes = self.route(goal_id, xy)
        if nodes is None:
            nodes = astar(
                self.graph, self.nearest_reachable_node(xy, goal_id=goal_id), goal_id, exclude_stairs=self.cfg.exclude_stairs,
                extra=self._coastal,
            )
        return self.plan(goal_id, nodes, pose).path

    def plan_length(self, goal_id: int, pose: np.ndarray) -> float:
        """Length (m) of the plan :meth:`plan_to` would make from the pose, without
        making it."""
        pts = self.plan_points(goal_id, pose)
        return float(np.hypot(*np.diff(pts, axis=0).T).sum())

    def plan(self, goal_id: int, nodes: list[int], pose: np.ndarray) -> Plan:
        """The plan from the pose through ``nodes``: its polyline, speed limits, narrow
        stretches and corners."""
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
        shortcuts = np.zeros((0, 4))
        if self._shortcuts is not None:
            plain = np.array([ab is None or (ab not in self._narrow_edges and self._edge_speed.get(ab, math.inf) >= self.cfg.cruise_speed_mps)
                              for ab in pairs], dtype=bool)
            keep_off = np.vstack([np.zeros((0, 2)), *(self._blocked_pts.get(e, np.zeros((0, 2))) for e in self.blocked)])
            keep, short = self._shortcuts.straighten(pts, plain, keep_off, self.avoid.radius_m)
            pairs = [None if sh else pairs[i] for i, sh in zip(keep[:-1], short, strict=True)]
            pts = pts[keep]
            shortcuts = np.hstack([pts[:-1], pts[1:]])[short]
        return Plan.along(
            self.cfg, self.avoid.robot_radius_m, goal_id, nodes, pts, pairs, self._edge_speed, self._narrow_edges, shortcuts
        )

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

    # -- blocked edges ------------------------------------------------------------------
    def prune_blocked(self, t: float) -> None:
        """Forget the marks that expired by ``t``."""
        for e in [e for e, until in self.blocked.items() if until <= t]:
            del self.blocked[e]
            self._blocked_pts.pop(e, None)

    def forget_blocked(self) -> None:
        """Forget every blocked edge (the next plan uses the whole graph)."""
        self.blocked.clear()
        self._blocked_pts.clear()

    def blocking_points(self, plan: Plan, pose: np.ndarray, located: np.ndarray, surroundings: Surroundings) -> np.ndarray:
        """The ``located`` obstacles (robot frame) on the plan's line ahead, in the world
        frame (through the pose): within the avoidance radius of the plan between that
        radius behind the robot's place on it and ``blocked_check_m`` ahead, and not
        explained by a map wall (none within ``near_wall_tol_m``)."""
        cfg, r = self.cfg, self.avoid.radius_m
        obs = np.asarray(located, dtype=np.float64).reshape(-1, 2)
        if not len(obs) or not len(plan.segments):
            return np.zeros((0, 2))
        xy = np.asarray(pose[:2], dtype=np.float64)
        c, sn = math.cos(float(pose[2])), math.sin(float(pose[2]))
        rel = np.column_stack([c * obs[:, 0] - sn * obs[:, 1], sn * obs[:, 0] + c * obs[:, 1]])  # world axes
        w = rel + xy
        # The stretch checked: each plan segment cut to arc lengths [s0 - r, s0 + check].
        s0 = plan.project(xy)
        lo, hi = s0 - r, s0 + cfg.blocked_check_m
        seg = np.flatnonzero((plan.cum[1:] > lo) & (plan.cum[:-1] < hi))
        a, d = plan.segments[seg, :2], plan.segments[seg, 2:] - plan.segments[seg, :2]
        L = np.maximum(plan.seg_len[seg], 1e-12)
        f0 = (np.clip(lo - plan.cum[seg], 0.0, None) / L)[:, None]
        f1 = (np.clip(hi - plan.cum[seg], None, plan.seg_len[seg]) / L)[:, None]
        on = (point_segment_distance(w, np.hstack([a + f0 * d, a + f1 * d])) < r).any(axis=1)
        rel, w = rel[on], w[on]
        if len(rel):
            walls = surroundings.near_walls(pose, float(np.max(np.hypot(rel[:, 0], rel[:, 1]))) + cfg.near_wall_tol_m)
            if len(walls):
                d2 = ((rel[:, None, :] - walls[None, :, :]) ** 2).sum(axis=-1).min(axis=1)
                w = w[d2 >= cfg.near_wall_tol_m**2]
        return w

    def mark_blocked(self, plan: Plan, pose: np.ndarray, located: np.ndarray, t: float, surroundings: Surroundings) -> bool:
        """Mark blocked (until ``t + blocked_edge_s``) the graph edges within the avoidance
        radius of the obstacle on the plan's line ahead (:meth:`blocking_points`): the
        plan's edges and those of its first node (the robot may stand on one of them,
        short of that node). True when an edge was not marked before."""
        cfg = self.cfg
        if cfg.blocked_edge_s <= 0 or not plan.nodes:
            return False
        pts = self.blocking_points(plan, pose, located, surroundings)
        if not len(pts):
            return False
        first = plan.nodes[0]
        cand = {edge_key(a, b) for a, b in zip(plan.nodes[:-1], plan.nodes[1:], strict=True)}
        cand |= {edge_key(e.s0_id, e.s1_id) for e in self.graph.edges if first in (e.s0_id, e.s1_id)}
        edges = sorted(cand)
        if not edges:
            return False
        nodes = self.graph.node_xy()
        segs = np.array([[*nodes[self.graph.index_of(a)], *nodes[self.graph.index_of(b)]] for a, b in edges], dtype=np.float64)
        dist = point_segment_distance(pts, segs)  # (points, edges)
        near = dist < self.avoid.radius_m
        if len(plan.shortcuts):
            # On a straightened stretch the obstacle may stand off every graph edge: it
            # blocks the edges' way nearest it (which the next plan's shortcuts keep off).
            on_short = (point_segment_distance(pts, plan.shortcuts) < self.avoid.radius_m).any(axis=1) & ~near.any(axis=1)
            near[np.flatnonzero(on_short), np.argmin(dist[on_short], axis=1)] = True
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

    def mark_unless_put_off(self, plan: Plan, pose: np.ndarray, located: np.ndarray, t: float, surroundings: Surroundings) -> None:
        """:meth:`mark_blocked`, and take the marks back when the re-plan round them is a
        long detour to put off for now (:meth:`_put_off_detour`)."""
        marks = self._marks()
        self.mark_blocked(plan, pose, located, t, surroundings)
        if self._put_off_detour(plan, pose, self.route(plan.goal, np.asarray(pose[:2])), t):
            self._restore_marks(marks)

    def replan_round_block(
        self, plan: Plan, pose: np.ndarray, located: np.ndarray, t: float, since: float, surroundings: Surroundings
    ) -> list[int] | None:
        """Blocked (Eq. 5 finds no open direction, or a back-off from what blocks is under
        way) without progress since ``since`` (the stuck clock's start) for
        ``blocked_wait_s``: mark the edges the obstacle stands on (:meth:`mark_blocked`)
        and re-plan. The nodes of a plan that goes round them; None when there is none
        (no other way: the marks were forgotten, or they are off the plan): the robot then
        waits as before, the stuck clock running on, and tries again only after some
        progress."""
        cfg = self.cfg
        if not (
            cfg.blocked_edge_s > 0
            and plan.goal is not None
            and t - since >= cfg.blocked_wait_s
            and since != self._waited_since
            and not self._detour_put_off(t)
        ):
            return None
        marks = self._marks()
        if not self.mark_blocked(plan, pose, located, t, surroundings):
            return None
        nodes = self.route(plan.goal, np.asarray(pose[:2]))
        if self._put_off_detour(plan, pose, nodes, t):
            self._restore_marks(marks)
            return None
        if nodes is None or nodes == plan.nodes:
            # No other way: the plan and the stuck clock stay as they were.
            if nodes is None:
                self.forget_blocked()
            self._waited_since = since
            return None
        return nodes

    def _marks(self) -> Marks:
        """The blocked edges' marks, to restore (:meth:`_restore_marks`)."""
        return dict(self.blocked), dict(self._blocked_pts), self.blocked_edges

    def _restore_marks(self, marks: Marks) -> None:
        self.blocked, self._blocked_pts, self.blocked_edges = dict(marks[0]), dict(marks[1]), marks[2]

    def _detour_put_off(self, t: float) -> bool:
        """Whether a long re-plan round a block is being put off at ``t``."""
        w = self.cfg.long_detour_wait_s
        return self._detour_from is not None and t - self._detour_from < w

    def _put_off_detour(self, plan: Plan, pose: np.ndarray, nodes: list[int] | None, t: float) -> bool:
        """Whether to put off, for now, the re-plan ``nodes`` round the edges marked
        blocked (:meth:`route` with the marks): it is longer than what is left of the
        plan by more than ``long_detour_m`` and the block has held less than
        ``long_detour_wait_s`` since such a re-plan was first put off (a first put-off
        more than three waits ago is forgotten: a new block)."""
        cfg = self.cfg
        if cfg.long_detour_wait_s <= 0 or plan.goal is None or len(plan.path) < 2:
            return False
        xy = np.asarray(pose[:2], dtype=np.float64)
        if nodes is None or nodes == plan.nodes:
            return False
        detour = self.plan(plan.goal, nodes, pose).length_m
        if detour <= float(plan.cum[-1]) - plan.project(xy) + cfg.long_detour_m:
            return False
        if self._detour_from is None or t - self._detour_from > 3.0 * cfg.long_detour_wait_s:
            self._detour_from = t
        return t - self._detour_from < cfg.long_detour_wait_s
