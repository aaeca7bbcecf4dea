"""The point-goal task of ``DepthNav-v0`` (dm_control's ``Task``): episodes, reward, observations.

Pure functions of the config, the site and the episode's state: which start and goal an
episode draws, the reward terms of a step (one small function each, summed in
``REWARD_TERMS`` order), when an episode ends, and the observation dict.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import relative_pose
from autonomy.maps.planner import dijkstra
from autonomy.perception.fspf import FSPFResult
from sim.envs.config import EnvConfig
from sim.envs.site import Site

#: Bound of the ``goal`` observation (metres); values beyond are clipped.
GOAL_LIMIT_M = 1000.0
#: Bound of positions in ``pose_estimate`` (metres).
POSITION_LIMIT_M = 1.0e4
REWARD_TERMS = ("progress", "success", "collision", "time")


@dataclass
class Episode:
    """One episode's task and what the reward and info read."""

    start: np.ndarray
    goal: np.ndarray
    goal_node: int
    """The navigation-graph node nearest the goal (the stack's navigator drives to it)."""
    steps: int = 0
    collisions: int = 0
    loc_resets: int = 0
    success: bool = False
    collided: bool = False
    phi: float = 0.0
    """Geodesic distance to the goal at the last step."""


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


# -- reward terms (each a small function of the step) ------------------------------------


def progress_reward(cfg: EnvConfig, phi_before: float, phi_after: float) -> float:
    """Reward per metre of geodesic progress towards the goal (negative when receding)."""
    return cfg.progress_reward_per_m * (phi_before - phi_after)


def success_reward(cfg: EnvConfig, first_success: bool) -> float:
    return cfg.success_reward if first_success else 0.0


def collision_reward(cfg: EnvConfig, new_contacts: int) -> float:
    return cfg.collision_reward * new_contacts


def time_reward(cfg: EnvConfig) -> float:
    return cfg.time_reward


# -- observations ------------------------------------------------------------------------


def goal_observation(reference_pose: np.ndarray, goal: np.ndarray, polar: bool = False) -> np.ndarray:
    """The goal in the robot frame of ``reference_pose``: (x, y) clipped to +-GOAL_LIMIT_M,
    or (distance, bearing) with the distance clipped to GOAL_LIMIT_M."""
    rel = relative_pose(reference_pose, np.array([goal[0], goal[1], 0.0]))[:2]
    if polar:
        return np.array([min(math.hypot(rel[0], rel[1]), GOAL_LIMIT_M), math.atan2(rel[1], rel[0])], dtype=np.float32)
    return np.clip(rel.astype(np.float32), -GOAL_LIMIT_M, GOAL_LIMIT_M)


def depth_observation(depth: np.ndarray, layout: str, dtype: str, depth_max_m: float) -> np.ndarray:
    """The depth frame (metres, 0 = invalid) in the observation's layout and type (a copy)."""
    if dtype == "uint8":
        d = np.where(depth > 0, np.clip(np.ceil(depth * (255.0 / depth_max_m)), 1, 255), 0).astype(np.uint8)
    else:
        d = depth.astype(np.float32, copy=True)
    if layout == "hwc":
        return d[:, :, None]
    if layout == "chw":
        return d[None, :, :]
    return d


def odometry_observation(increment: np.ndarray) -> np.ndarray:
    return np.clip(increment.astype(np.float32), np.array([-1, -1, -np.pi], np.float32), np.array([1, 1, np.pi], np.float32))


def pose_estimate_observation(estimate: np.ndarray, spread: tuple[float, float]) -> np.ndarray:
    L = POSITION_LIMIT_M
    pe = np.array([estimate[0], estimate[1], estimate[2], spread[0], spread[1]], dtype=np.float32)
    return np.clip(pe, np.array([-L, -L, -np.pi, 0, 0], np.float32), np.array([L, L, np.pi, L, 10.0], np.float32))


def points_observation(
    planes: FSPFResult | None, n_cap: int, low: np.ndarray, high: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """FSPF's points (plane points first, then outliers), padded or subsampled to ``n_cap``."""
    out = np.zeros((n_cap, 8), dtype=np.float32)
    if planes is None:
        return out
    n_p, n_o = len(planes.points), len(planes.outliers)
    total = n_p + n_o
    if total == 0:
        return out
    idx = np.arange(total)
    if total > n_cap:
        idx = np.sort(rng.choice(total, n_cap, replace=False))
    k = len(idx)
    is_p = idx < n_p
    ip, io = idx[is_p], idx[~is_p] - n_p
    m = len(ip)
    out[:m, :3] = planes.points[ip]
    out[:m, 3:6] = planes.normals[ip]
    out[:m, 6] = 1.0
    out[m:k, :3] = planes.outliers[io]
    out[:k, 7] = 1.0
    np.clip(out, low, high, out=out)
    return out
