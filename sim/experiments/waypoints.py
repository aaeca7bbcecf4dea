"""A waypoint mission: the waypoints, the start pose, and the bookkeeping of each leg.

The robot's navigator says when it has arrived (on its estimate); the mission checks the
truth, counts the waypoint reached, failed on a timeout, or reached at the wrong place,
and hands the navigator the next goal. A long run draws one random waypoint at a time
until the robot has driven the target distance.

Random waypoints come from the navigation graph's largest connected component (a graph
made from the walls has one component per closed room); given waypoints and a given
start must lie in one component.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from autonomy.common.errors import InputError
from autonomy.maps.graph_builder import graph_components
from autonomy.maps.navgraph import NavGraph
from sim.scenario import MissionConfig

#: A waypoint counts as reached when the true position is this much beyond the
#: navigator's arrival radius from it (the navigator arrives on its estimate).
ARRIVAL_TRUTH_MARGIN_M = 0.5
#: The automatic leg timeout: this many seconds ...
LEG_TIMEOUT_BASE_S = 30.0
#: ... plus this many times the leg's nominal time at cruise speed.
LEG_TIMEOUT_FACTOR = 2.0
#: The budget follows the plan: when the navigator re-plans (round a passage a person or a
#: piece of furniture blocks), the budget becomes what has been used plus the automatic
#: timeout of what is left of the new plan, if that is more, but never more than this
#: many times the leg's first budget (a robot that re-plans without end still fails).
LEG_TIMEOUT_MAX_FACTOR = 3.0


@dataclass
class Mission:
    """Waypoint sequence and the state of the leg being driven."""

    waypoints: list[int]
    start_pose: np.ndarray
    current: int = 0
    started_at: float = 0.0
    timeout_s: float = 0.0
    first_timeout_s: float = 0.0
    """The leg's budget when it started (:data:`LEG_TIMEOUT_MAX_FACTOR`)."""
    plan: tuple[int, ...] = ()
    """The navigator's plan (its graph nodes) the budget was last set for."""
    rearmed: int = 0
    """How many times the current leg's budget grew with a re-plan."""
    reached: int = 0
    failed: int = 0
    events: list[dict] = field(default_factory=list)
    pool: list[int] = field(default_factory=list)
    """Node ids a long run draws its next waypoints from (the mission's component)."""

    @property
    def done(self) -> bool:
        return self.current >= len(self.waypoints)

    @property
    def goal(self) -> int:
        return self.waypoints[self.current]

    @property
    def unvisited(self) -> int:
        """Waypoints not attempted to the end (the run's time ran out)."""
        return len(self.waypoints) - self.current


def plan_mission(m: MissionConfig, graph: NavGraph, rng: np.random.Generator) -> Mission:
    """Waypoints (given or random) and the start pose on the first path edge."""
    ids = [int(i) for i in graph.node_ids()]
    known = set(ids)
    for w in m.waypoints:
        if w not in known:
            raise InputError(f"mission.waypoints: node id {w} is not in the navigation graph")
    if m.start_node >= 0 and m.start_node not in known:
        raise InputError(f"mission.start_node: node id {m.start_node} is not in the navigation graph")
    pool = _component_pool(m, graph, ids)
    wps = list(m.waypoints) if m.waypoints else _random_waypoints(m, pool, rng)
    start = m.start_node if m.start_node >= 0 else None
    if start is None:
        nbrs = graph.neighbors(wps[0])
        start = int(nbrs[0]) if nbrs else wps[0]
        if len(wps) == 1 and start == wps[0]:
            raise InputError("mission: a single waypoint with no graph neighbour; give mission.start_node")
    xy = graph.node_xy()
    p = xy[graph.index_of(start)]
    q = xy[graph.index_of(wps[0])]
    heading = math.atan2(q[1] - p[1], q[0] - p[0]) if np.hypot(*(q - p)) > 1e-6 else 0.0
    return Mission(waypoints=wps, start_pose=np.array([p[0], p[1], heading]), pool=pool)


def _component_pool(m: MissionConfig, graph: NavGraph, ids: list[int]) -> list[int]:
    """The node ids of the mission's connected component: the start's (or the first given
    waypoint's) when waypoints are given, else the largest. A given node in another
    component is a one-line InputError."""
    comp = dict(zip(ids, graph_components(len(ids), graph.edge_indices()).tolist(), strict=True))
    if m.waypoints:
        ref_node = m.start_node if m.start_node >= 0 else m.waypoints[0]
        ref = comp[ref_node]
        for w in m.waypoints:
            if comp[w] != ref:
                raise InputError(
                    f"mission.waypoints: node id {w} cannot be reached from node {ref_node} "
                    "(they are in separate parts of the navigation graph)"
                )
    else:
        ref = 0
        if m.start_node >= 0 and comp[m.start_node] != 0:
            raise InputError(
                f"mission.start_node: node id {m.start_node} is not in the navigation graph's largest "
                "connected part, which random waypoints are drawn from (a room without a door has its own part)"
            )
    pool = [i for i in ids if comp[i] == ref]
    if not m.waypoints and len(pool) < 2:
        raise InputError("mission: random waypoints need a navigation graph with two connected nodes")
    return pool


def _random_waypoints(m: MissionConfig, ids: list[int], rng: np.random.Generator) -> list[int]:
    """Random waypoints, none the same as the one before; a long run draws one at a time."""
    wps: list[int] = []
    prev = m.start_node if m.start_node >= 0 else None
    n_first = 1 if m.target_distance_m > 0 else m.n_random_waypoints
    while len(wps) < n_first:
        c = int(rng.choice(ids))
        if c != prev:
            wps.append(c)
            prev = c
    return wps


def leg_timeout(m: MissionConfig, length_m: float, cruise_speed_mps: float) -> float:
    """How long a leg of ``length_m`` may take before its waypoint counts as failed."""
    if m.waypoint_timeout_s > 0:
        return m.waypoint_timeout_s
    return LEG_TIMEOUT_BASE_S + LEG_TIMEOUT_FACTOR * length_m / cruise_speed_mps


def start_leg(mission: Mission, m: MissionConfig, length_m: float, plan: list[int], t: float, cruise_speed_mps: float) -> None:
    """Start the current leg at ``t`` on a plan of ``length_m`` (its graph nodes ``plan``)."""
    mission.started_at = t
    mission.timeout_s = mission.first_timeout_s = leg_timeout(m, length_m, cruise_speed_mps)
    mission.plan = tuple(plan)
    mission.rearmed = 0


def follow_plan(mission: Mission, m: MissionConfig, plan: list[int], remaining_m: float, t: float, cruise_speed_mps: float) -> None:
    """The leg's budget after the navigator's plan became ``plan`` with ``remaining_m`` left
    (:data:`LEG_TIMEOUT_MAX_FACTOR`); a timeout the mission gives stays as given."""
    key = tuple(plan)
    if key == mission.plan or m.waypoint_timeout_s > 0:
        return
    mission.plan = key
    used = t - mission.started_at
    budget = min(used + leg_timeout(m, remaining_m, cruise_speed_mps), LEG_TIMEOUT_MAX_FACTOR * mission.first_timeout_s)
    if budget > mission.timeout_s:
        mission.timeout_s = budget
        mission.rearmed += 1


def close_leg(
    mission: Mission, m: MissionConfig, graph: NavGraph, *, arrived: bool, timed_out: bool, truth_xy: np.ndarray, t: float,
    distance_m: float, arrival_radius_m: float, rng: np.random.Generator, recovering: bool = False,
) -> None:
    """Count the current waypoint (reached, timeout or wrong place), log the event, and
    move on; a long run short of its distance draws the next random waypoint, and so does
    one past it while ``recovering`` (a localization failure or a relocalization under
    way), so that the run sees the recovery to its end instead of cutting it off."""
    node = mission.goal
    goal_xy = graph.node_xy()[graph.index_of(node)]
    ok = arrived and np.hypot(*(goal_xy - truth_xy)) < arrival_radius_m + ARRIVAL_TRUTH_MARGIN_M
    mission.reached += int(ok)
    mission.failed += int(not ok)
    mission.events.append(
        {
            "t": round(t, 3),
            "waypoint": node,
            "status": "reached" if ok else ("timeout" if timed_out else "wrong_place"),
            "leg_s": round(t - mission.started_at, 3),
            "distance_m": round(distance_m, 2),
            **(
                {"budget_s": round(mission.timeout_s, 1), "first_budget_s": round(mission.first_timeout_s, 1), "rearmed": mission.rearmed}
                if mission.rearmed
                else {}
            ),
        }
    )
    mission.current += 1
    mission.started_at = t
    if m.target_distance_m > 0 and (distance_m < m.target_distance_m or recovering) and mission.done:
        ids = mission.pool or [int(i) for i in graph.node_ids()]
        if len(ids) < 2:
            return
        nxt = node
        while nxt == node:
            nxt = int(rng.choice(ids))
        mission.waypoints.append(nxt)
