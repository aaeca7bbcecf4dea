"""A building to simulate: its map and navigation graph, and random furniture and people in it.

The scenario runner and the gymnasium env place furniture and route people through the
same functions here, so a scenario and an env episode drawn from the same seed furnish and
populate a building the same way.

A map given by its walls alone gets its navigation graph from
:func:`autonomy.maps.graph_builder.load_or_build_navgraph` (:func:`navgraph_from_walls`), and
random furniture goes anywhere in the free space where the map has no zones (open areas
or rooms). Such a graph can have several connected components (a room without a door
is one of its own): starts, goals, waypoints and people's routes come from the largest
(:func:`main_component_ids`).
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from autonomy.common.constants import ROBOT_RADIUS_M
from autonomy.common.errors import InputError
from autonomy.common.geometry import point_segment_distance
from autonomy.maps.freespace import FreeSpace, FreeSpaceConfig, build_free_space
from autonomy.maps.graph_builder import GraphBuildConfig, cached_navgraph, graph_components
from autonomy.maps.navgraph import NavGraph
from autonomy.maps.planner import astar, path_points
from autonomy.maps.vectormap import VectorMap
from autonomy.navigation.avoidance import AvoidanceConfig
from sim.simulator.actors import Furniture, Person

#: Kinds of random furniture, drawn uniformly.
FURNITURE_KINDS = ("table", "chair", "box", "cabinet")
#: A piece keeps this much beyond its half-diagonal and the robot radius from every graph edge ...
EDGE_CLEARANCE_M = 0.15
#: ... this much beyond its half-diagonal from every wall ...
WALL_CLEARANCE_M = 0.05
#: ... and this much between its footprint circle and any other piece's.
PIECE_GAP_M = 0.1
#: Tries per piece before random placement gives up.
TRIES_PER_PIECE = 500
#: A random person's route is a shortest graph path longer than this.
MIN_ROUTE_M = 3.0


@dataclass
class Building:
    """A map with its graph, (if known) its zones, and the map file it came from.

    Its free space (per robot radius) and the node ids of its graph's largest connected
    component are computed on first use and kept: the free space of a 100 x 100 m map
    takes about 0.3 s, and an env reuses one building for many episodes."""

    vectormap: VectorMap
    navgraph: NavGraph
    open_areas: tuple[tuple[float, float, float, float], ...] = ()
    rooms: tuple[tuple[float, float, float, float], ...] = ()
    map_path: Path | None = None
    open_map: bool | None = None
    """Whether the map is open (its free space the walls' convex hull), closed, or None:
    told from the walls (:attr:`autonomy.maps.freespace.FreeSpaceConfig.open_map`)."""
    _free: dict[float, FreeSpace] = field(default_factory=dict, init=False, repr=False, compare=False)
    _main: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    def __getstate__(self) -> dict:
        # The caches are large grids and quick to remake: a pickled building leaves them out.
        state = dict(self.__dict__)
        state.update(_free={}, _main=None)
        return state

    @property
    def furniture_zones(self) -> tuple[tuple[float, float, float, float], ...]:
        """Where random furniture goes: the open areas, else the rooms (empty: the free space)."""
        return self.open_areas or self.rooms

    def free_space(self, robot_radius_m: float = ROBOT_RADIUS_M) -> FreeSpace:
        """Where a robot of this radius fits inside the building (one-line InputError when
        nowhere); computed once per radius."""
        key = float(robot_radius_m)
        if key not in self._free:
            self._free[key] = build_free_space(self.vectormap, FreeSpaceConfig(robot_radius_m=key, open_map=self.open_map))
        return self._free[key]

    def free_spot(self, rng: np.random.Generator, clearance_m: float, robot_radius_m: float) -> np.ndarray | None:
        """A point uniform over the largest free region at least ``clearance_m`` from every
        wall (:meth:`autonomy.maps.freespace.FreeSpace.sample`); None when there is no such place."""
        try:
            return self.free_space(robot_radius_m).sample(rng, 1, clearance_m)[0]
        except InputError:
            return None

    def prepare_free_spots(self, clearance_m: float, robot_radius_m: float) -> None:
        """Build now what :meth:`free_spot` draws from (the free space and its cells, about
        20 MB for the corridor-loop building), so that a run that will draw places later
        has its memory steady from its start."""
        self.free_space(robot_radius_m).sample_cells(clearance_m)

    @property
    def main_node_ids(self) -> np.ndarray:
        """Node ids (in node order) of the graph's largest connected component."""
        if self._main is None:
            self._main = main_component_ids(self.navgraph)
        return self._main


def main_component_ids(graph: NavGraph) -> np.ndarray:
    """Node ids (in node order) of the graph's largest connected component: all of them
    for a connected graph."""
    ids = graph.node_ids()
    if ids.size == 0:
        return ids
    return ids[graph_components(graph.n_nodes, graph.edge_indices()) == 0]


def navgraph_from_walls(
    vm: VectorMap, map_path: str | os.PathLike[str] | None, avoidance: AvoidanceConfig, *, quiet: bool = False,
    open_map: bool | None = None,
) -> NavGraph:
    """The navigation graph made from the walls for the robot whose obstacle avoidance is
    ``avoidance``, cached beside the map file (or under ~/.cache/depthnav). Its edges keep
    the avoidance's own clearance (robot radius plus safety margin) from every wall: a
    narrower passage is one the avoidance will not let the robot through (Eq. 3-4 block
    it), and an edge through it would hold the robot at its mouth until the leg times
    out. ``open_map``: the map is open, closed, or (None) told from the walls
    (:attr:`autonomy.maps.freespace.FreeSpaceConfig.open_map`). When made rather than read
    from the cache, one line on stderr (unless ``quiet``) says so and where it is kept."""
    cfg = GraphBuildConfig(
        free_space=FreeSpaceConfig(robot_radius_m=avoidance.robot_radius_m, open_map=open_map), margin_m=avoidance.safety_margin_m
    )
    got = cached_navgraph(vm, map_path, cfg)
    if got.built and not quiet:
        name = Path(map_path).name if map_path is not None else (vm.name or "the map")
        kept = f"cached in {os.path.normpath(got.path)}" if got.path is not None else "not cached (no writable place)"
        g = got.graph
        print(f"{name}: navigation graph made from the walls ({g.n_nodes} nodes, {g.n_edges} edges), {kept}", file=sys.stderr)
    return got.graph


def draw_furniture(
    zones: tuple[tuple[float, float, float, float], ...], rng: np.random.Generator, kind: str | None = None
) -> Furniture:
    """One piece at a uniform place and heading in a random zone (kind drawn if not given)."""
    z = zones[rng.integers(len(zones))]
    if kind is None:
        kind = str(FURNITURE_KINDS[rng.integers(len(FURNITURE_KINDS))])
    return Furniture(kind=kind, x=float(rng.uniform(z[0], z[2])), y=float(rng.uniform(z[1], z[3])), yaw=float(rng.uniform(-math.pi, math.pi)))


def furniture_fits(
    f: Furniture, placed: list[Furniture], edges: np.ndarray, walls: np.ndarray, robot_radius_m: float
) -> bool:
    """Whether a piece keeps the graph drivable (its half-diagonal plus the robot radius
    plus ``EDGE_CLEARANCE_M`` from every edge), clears the walls and the pieces placed."""
    half = f.half_diagonal
    p = np.array([f.x, f.y])
    if len(edges) and point_segment_distance(p, edges).min() < half + robot_radius_m + EDGE_CLEARANCE_M:
        return False
    if len(walls) and point_segment_distance(p, walls).min() < half + WALL_CLEARANCE_M:
        return False
    return not any(math.hypot(o.x - f.x, o.y - f.y) < half + o.half_diagonal + PIECE_GAP_M for o in placed)


def draw_furniture_in_free_space(
    building: Building, rng: np.random.Generator, robot_radius_m: float, kind: str | None = None
) -> Furniture | None:
    """One piece at a uniform place in the building's largest free region, its
    half-diagonal plus ``WALL_CLEARANCE_M`` from every wall, at a uniform heading (kind
    drawn if not given); None when no place is that far from the walls."""
    if kind is None:
        kind = str(FURNITURE_KINDS[rng.integers(len(FURNITURE_KINDS))])
    xy = building.free_spot(rng, Furniture(kind=kind).half_diagonal + WALL_CLEARANCE_M, robot_radius_m)
    if xy is None:
        return None
    return Furniture(kind=kind, x=float(xy[0]), y=float(xy[1]), yaw=float(rng.uniform(-math.pi, math.pi)))


def _draw_piece(building: Building, rng: np.random.Generator, robot_radius_m: float, kind: str | None = None) -> Furniture | None:
    """A candidate piece: in a zone when the map has zones, else anywhere in the free space."""
    zones = building.furniture_zones
    if zones:
        return draw_furniture(zones, rng, kind)
    return draw_furniture_in_free_space(building, rng, robot_radius_m, kind)


def random_furniture(building: Building, n: int, rng: np.random.Generator, robot_radius_m: float) -> tuple[Furniture, ...]:
    """``n`` pieces of random kinds in the building's open areas (or rooms; the free space
    when it has neither), clear of walls, of each other and of the navigation graph's edges."""
    if n == 0:
        return ()
    edges = building.navgraph.edge_segments()
    walls = np.asarray(building.vectormap.segments)
    out: list[Furniture] = []
    for _ in range(TRIES_PER_PIECE * n):
        if len(out) == n:
            break
        f = _draw_piece(building, rng, robot_radius_m)
        if f is not None and furniture_fits(f, out, edges, walls, robot_radius_m):
            out.append(f)
    if len(out) < n:
        where = "open areas" if building.furniture_zones else "free space"
        raise InputError(f"actors.random_furniture: only {len(out)} of {n} pieces fit in the map's {where} clear of the nav graph")
    return tuple(out)


def replace_furniture(
    building: Building, pieces: list[Furniture], fixed: int, rng: np.random.Generator, robot_radius_m: float, park: tuple[float, float]
) -> list[Furniture]:
    """New places for ``pieces[fixed:]`` (kinds kept), as :func:`random_furniture` places
    them; a piece that does not fit in ``TRIES_PER_PIECE`` tries is parked at ``park``
    (outside the building), offset 10 m per piece."""
    edges = building.navgraph.edge_segments()
    walls = np.asarray(building.vectormap.segments)
    placed = list(pieces[:fixed])
    for k in range(fixed, len(pieces)):
        new = replace(pieces[k], x=park[0] - 10.0 * k, y=park[1])
        for _ in range(TRIES_PER_PIECE):
            f = _draw_piece(building, rng, robot_radius_m, pieces[k].kind)
            if f is not None and furniture_fits(f, placed, edges, walls, robot_radius_m):
                new = f
                break
        placed.append(new)
    return placed


def random_people(graph: NavGraph, n: int, rng: np.random.Generator, nodes: np.ndarray | None = None) -> tuple[Person, ...]:
    """People walking back and forth along random shortest paths of the nav graph, between
    ``nodes`` (default: the graph's largest connected component)."""
    out: list[Person] = []
    ids = main_component_ids(graph) if nodes is None else np.asarray(nodes)
    if len(ids) < 2:
        return ()
    for _ in range(n):
        for _attempt in range(20):
            a, b = (int(v) for v in rng.choice(ids, 2, replace=False))
            try:
                path = astar(graph, a, b)
            except InputError:
                continue
            pts = path_points(graph, path)
            if len(pts) >= 2 and np.sum(np.hypot(*np.diff(pts, axis=0).T)) > MIN_ROUTE_M:
                route = tuple((float(x), float(y)) for x, y in pts)
                out.append(Person(route=route, speed_mps=float(rng.uniform(0.9, 1.4)), start_offset_m=float(rng.uniform(0, 20))))
                break
    return tuple(out)
