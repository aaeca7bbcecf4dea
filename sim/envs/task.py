"""The point-goal task of ``DepthNav-v0`` (dm_control's ``Task``): what an episode is and how it starts.

An :class:`Episode` holds one episode's task and the state its reward and info read;
:func:`begin_episode` sets the site up for a new one (actors, start, goal) from the
episode's seeds. The reward terms are in :mod:`sim.envs.reward`, the observations in
:mod:`sim.envs.observation`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import wrap_angle
from autonomy.maps.planner import dijkstra
from sim.envs.config import EnvConfig
from sim.envs.geometry import GeodesicField
from sim.envs.site import Site
from sim.simulator.step import EpisodeSeeds


@dataclass
class Episode:
    """One episode's task and the state the reward and info read."""

    start: np.ndarray
    goal: np.ndarray
    goal_node: int
    """The navigation-graph node nearest the goal (the stack's navigator drives to it)."""
    field: GeodesicField
    """Geodesic distances to the goal (the progress reward, the rendered route)."""
    steps: int = 0
    collisions: int = 0
    loc_resets: int = 0
    success: bool = False
    collided: bool = False
    phi: float = 0.0
    """Geodesic distance to the goal at the last step."""
    penalised: int = 0
    """Collisions penalised so far (``collision_penalties``)."""
    penalised_t: float = -math.inf
    """When the last penalised collision started (s from the episode's start)."""


def begin_episode(
    cfg: EnvConfig, site: Site, seeds: EpisodeSeeds, start: np.ndarray | None = None, goal: np.ndarray | None = None
) -> Episode:
    """Set ``site`` up for a new episode: random furniture and people, and the robot at the
    start. The start and goal are drawn from ``seeds.mission`` unless given."""
    if cfg.n_furniture:
        site.place_furniture(cfg, seeds.actors)
    site.route_people(cfg, seeds.actors)
    start_xyt, goal_xy, goal_node = sample_task(cfg, site, seeds.mission)
    if start is not None:
        start_xyt = start
    if goal is not None:
        goal_xy, goal_node = goal, nearest_node(site, goal)
    start_xyt[2] = wrap_angle(start_xyt[2])
    site.clear_start(cfg, start_xyt[:2], seeds.actors)
    site.world.reset(tuple(start_xyt))
    field = GeodesicField(site.building.navgraph, site.walls, goal_xy, cfg.geodesic_radius_m)
    return Episode(start=start_xyt.copy(), goal=goal_xy, goal_node=goal_node, field=field)


def sample_task(cfg: EnvConfig, site: Site, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, int]:
    """A start node (random heading) and a goal node at a geodesic distance within
    ``[min_goal_distance_m, max_goal_distance_m]`` (the farthest reachable if none is);
    unless given, both from the graph's largest connected component."""
    g = site.building.navgraph
    ids = [int(i) for i in site.building.main_node_ids]
    xy = g.node_xy()
    starts = list(cfg.start_nodes) or ids
    goals = list(cfg.goal_nodes) or ids
    hi = cfg.max_goal_distance_m or math.inf
    choice = None
    fallback = None
    for _ in range(30):
        s = starts[int(rng.integers(len(starts)))]
        d, _ = dijkstra(site.adj, {g.index_of(s): 0.0})
        dg = np.array([d[g.index_of(t)] if t != s else np.inf for t in goals])
        ok = np.flatnonzero((dg >= cfg.min_goal_distance_m) & (dg <= hi))
        if len(ok):
            choice = (s, goals[int(ok[rng.integers(len(ok))])])
            break
        finite = np.flatnonzero(np.isfinite(dg))
        if len(finite) and fallback is None:
            fallback = (s, goals[int(finite[np.argmax(dg[finite])])])
    choice = choice or fallback
    if choice is None:
        raise InputError("DepthNav: no goal node is reachable from the start nodes in the navigation graph")
    s, t = choice
    p = xy[g.index_of(s)]
    start = np.array([p[0], p[1], rng.uniform(-math.pi, math.pi)])
    return start, xy[g.index_of(t)].astype(np.float64).copy(), int(t)


def nearest_node(site: Site, xy: np.ndarray) -> int:
    g = site.building.navgraph
    nodes = g.node_xy()
    return int(g.node_ids()[int(np.argmin(np.hypot(nodes[:, 0] - xy[0], nodes[:, 1] - xy[1])))])
