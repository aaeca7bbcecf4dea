"""The blockage fault's placement (:class:`FaultBlockage`): where across the robot's way a
corridor can be blocked with another way left, and the panels stood there and parked after.

The way is the simulator's own (the navigation graph's shortest path from the node
nearest the true pose to the mission's waypoint), never the robot's plan, so where a
blockage lands does not depend on what the robot believes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import (
    point_segment_distance,
    point_segment_projection,
    segment_distances,
)
from autonomy.maps.graph_builder import graph_components
from autonomy.maps.planner import astar, path_points
from sim.simulator.fault_config import PANEL_WIDTH_M, TIME_EPS_S, FaultParams
from sim.simulator.fault_scene import FaultScene

#: A blockage stands this far ahead of the robot along its way to the waypoint (min, max) ...
BLOCKAGE_AHEAD_M = (4.0, 8.0)
#: ... at one of the places this far apart.
BLOCKAGE_STEP_M = 0.25
#: A blockage keeps this much beyond the robot's radius from the robot.
BLOCKAGE_ROBOT_GAP_M = 0.5
#: A blockage due where there is no such place (an open hall, no waypoint) waits for one,
#: looking every this many seconds ...
BLOCKAGE_RETRY_S = 0.5
#: ... while the robot drives up to this far (then it is recorded as skipped).
BLOCKAGE_WAIT_M = 50.0

Spot = tuple[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray]
"""Where a blockage stands: the line's ends (a, b), the way's direction there, the
distance ahead and the graph edges the line cuts."""


@dataclass(frozen=True)
class PendingBlockage:
    """A blockage that is due and waits for a place: its parameters, what triggered it,
    and the time and distance it fell due at."""

    params: FaultParams
    trigger: str
    due_t: float
    due_m: float


def _yaw_quat(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def ray_to_walls(origin: np.ndarray, direction: np.ndarray, walls: np.ndarray) -> float:
    """Distance along a unit ``direction`` from ``origin`` to the first wall (N, 4) it
    meets (inf when none)."""
    a, e = walls[:, :2], walls[:, 2:] - walls[:, :2]
    ao = a - origin
    den = direction[0] * e[:, 1] - direction[1] * e[:, 0]
    ok = np.abs(den) > 1e-12
    den = np.where(ok, den, 1.0)
    t = (ao[:, 0] * e[:, 1] - ao[:, 1] * e[:, 0]) / den
    u = (ao[:, 0] * direction[1] - ao[:, 1] * direction[0]) / den
    hit = ok & (t > 1e-9) & (u >= 0.0) & (u <= 1.0)
    return float(t[hit].min()) if hit.any() else math.inf


class FaultBlockage:
    """The blockage's panels (``panels``: indices into the world's furniture, parked
    outside the building when not in use), the blockage waiting for a place, and the
    search for one."""

    def __init__(self, scene: FaultScene, rng: np.random.Generator, panels: list[int], max_width_m: float) -> None:
        self.scene = scene
        self.rng = rng
        self.panels = panels
        """The world's furniture pieces that make up a blockage."""
        self.max_width_m = max_width_m
        """The widest corridor a blockage spans."""
        self.waiting: PendingBlockage | None = None
        """A blockage that is due, until it finds a place (or is skipped)."""
        self._next_try = -math.inf

    def bodies(self) -> np.ndarray:
        """MuJoCo body ids of the panels."""
        return self.scene.furniture_bodies[self.panels]

    def wait(self, params: FaultParams, trigger: str, t: float, distance_m: float) -> None:
        """A blockage falls due: look for a place from this tick on."""
        self.waiting, self._next_try = PendingBlockage(params, trigger, float(t), float(distance_m)), -math.inf

    def looks_now(self, t: float) -> bool:
        """Whether a blockage waits and it is time to look for its place again."""
        return self.waiting is not None and t >= self._next_try - TIME_EPS_S

    def look(self, t: float, distance_m: float, goal: int | None) -> tuple[PendingBlockage, Spot | None] | None:
        """The waiting blockage and its place if there is one now on the way to the
        waypoint ``goal``, or with no place (to record as skipped) once the robot has
        driven ``BLOCKAGE_WAIT_M`` since it fell due; None while it waits on."""
        pending = self.waiting
        assert pending is not None
        pose = self.scene.pose()
        spot = self.spot(pose, self.route(pose, goal))
        if spot is None and distance_m - pending.due_m < BLOCKAGE_WAIT_M:
            self._next_try = t + BLOCKAGE_RETRY_S
            return None
        self.waiting = None
        return pending, spot

    def place(self, rec: dict, spot: Spot | None) -> bool:
        """Stand the panels (as many as the corridor's width needs) along the line of
        ``spot``, recording where; False (recorded as skipped) without a spot."""
        if spot is None:
            rec["skipped"] = (
                f"no corridor up to {self.max_width_m} m wide {BLOCKAGE_AHEAD_M[0]}-{BLOCKAGE_AHEAD_M[1]} m "
                f"ahead on the way to the waypoint with another route to it within {BLOCKAGE_WAIT_M} m driven"
            )
            return False
        a, b, d, ahead, cut = spot
        width = float(np.hypot(*(b - a)))
        n = math.ceil(width / PANEL_WIDTH_M - 1e-9)
        u = (b - a) / width
        yaw = math.atan2(d[1], d[0])
        model = self.scene.world.model
        for k, i in enumerate(self.panels):
            bid = self.scene.furniture_bodies[i]
            if k < n:
                c = a + u * (0.5 * PANEL_WIDTH_M + (width - PANEL_WIDTH_M) * (k / (n - 1) if n > 1 else 0.5))
                model.body_pos[bid] = [c[0], c[1], 0.0]
                model.body_quat[bid] = _yaw_quat(yaw)
        mujoco.mj_forward(model, self.scene.world.data)
        graph = self.scene.building.navgraph
        rec["where"] = {
            "centre": [float(v) for v in 0.5 * (a + b)],
            "ends": [[float(v) for v in a], [float(v) for v in b]],
            "width_m": width,
            "ahead_m": ahead,
            "panels": n,
            "cut_edges": [[int(graph.edges[j].s0_id), int(graph.edges[j].s1_id)] for j in cut],
        }
        return True

    def park(self) -> None:
        """The panels back where they are parked."""
        world = self.scene.world
        model = world.model
        for i in self.panels:
            f, bid = world.furniture[i], self.scene.furniture_bodies[i]
            model.body_pos[bid] = [f.x, f.y, 0.0]
            model.body_quat[bid] = _yaw_quat(f.yaw)
        mujoco.mj_forward(model, world.data)

    def route(self, pose: np.ndarray, goal: int | None) -> np.ndarray | None:
        """The way (K, 2) from the true pose to the waypoint ``goal``: the pose, then the
        navigation graph's shortest path from the node nearest it (:func:`astar`); None
        without a waypoint or a path."""
        if goal is None:
            return None
        graph = self.scene.building.navgraph
        try:
            nodes = astar(graph, graph.nearest_node(float(pose[0]), float(pose[1])), int(goal))
        except InputError:
            return None
        return np.vstack([np.asarray(pose[:2], dtype=np.float64), path_points(graph, nodes)])

    def spot(self, pose: np.ndarray, way_xy: np.ndarray | None) -> Spot | None:
        """Ends (a, b) of a wall-to-wall line across the way ``way_xy`` 4-8 m ahead, the
        way's direction there, the distance ahead and the graph edges it cuts; None when no
        place there is a corridor (up to ``max_width_m``) whose blocking leaves the
        graph a way from the robot to the way's end."""
        if way_xy is None or len(way_xy) < 2 or not len(self.panels):
            return None
        way = np.asarray(way_xy, dtype=np.float64).reshape(-1, 2)
        segs = np.concatenate([way[:-1], way[1:]], axis=1)
        lengths = np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
        cum = np.concatenate([[0.0], np.cumsum(lengths)])
        frac, dist = point_segment_projection(pose[:2], segs)
        k0 = int(np.argmin(dist))
        s0 = cum[k0] + frac[k0] * lengths[k0]
        ahead = np.arange(BLOCKAGE_AHEAD_M[0], BLOCKAGE_AHEAD_M[1] + 1e-9, BLOCKAGE_STEP_M)
        ahead = ahead[s0 + ahead < cum[-1]]
        if not len(ahead):
            return None
        graph = self.scene.building.navgraph
        walls, radius = self.scene.walls, self.scene.robot_radius_m
        edges, edge_ij = graph.edge_segments(), graph.edge_indices()
        src = graph.index_of(graph.nearest_node(float(pose[0]), float(pose[1])))
        dst = graph.index_of(graph.nearest_node(float(way[-1, 0]), float(way[-1, 1])))
        for s_ahead in np.roll(ahead, -int(self.rng.integers(len(ahead)))):
            s = s0 + s_ahead
            k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(segs) - 1))
            if lengths[k] <= 1e-9:
                continue
            d = (segs[k, 2:] - segs[k, :2]) / lengths[k]
            p = segs[k, :2] + (s - cum[k]) * d
            n = np.array([-d[1], d[0]])
            left, right = ray_to_walls(p, n, walls), ray_to_walls(p, -n, walls)
            width = left + right
            if not (2.0 * radius <= width <= self.max_width_m):
                continue
            a, b = p - right * n, p + left * n
            line = np.concatenate([a, b])
            if point_segment_distance(pose[:2], line[None])[0] < radius + BLOCKAGE_ROBOT_GAP_M:
                continue
            cut = np.flatnonzero(segment_distances(edges, np.tile(line, (len(edges), 1))) < radius)
            if not len(cut):
                continue
            comp = graph_components(graph.n_nodes, np.delete(edge_ij, cut, axis=0))
            if src != dst and comp[src] == comp[dst]:
                return a, b, d, float(s_ahead), cut
        return None
