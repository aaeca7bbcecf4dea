"""A building to simulate: its map and navigation graph, and random furniture and people in it.

The scenario runner and the gymnasium env place furniture and route people through the
same functions here, so a scenario and an env episode drawn from the same seed furnish and
populate a building the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from autonomy.errors import InputError
from autonomy.geometry import point_segment_distance
from autonomy.planner import astar, path_points
from autonomy.vectormap import NavGraph, VectorMap
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
    """A map with its graph, (if known) its zones, and the map file it came from."""

    vectormap: VectorMap
    navgraph: NavGraph
    open_areas: tuple[tuple[float, float, float, float], ...] = ()
    rooms: tuple[tuple[float, float, float, float], ...] = ()
    map_path: Path | None = None

    @property
    def furniture_zones(self) -> tuple[tuple[float, float, float, float], ...]:
        """Where random furniture goes: the open areas, else the rooms."""
        return self.open_areas or self.rooms


def _half_diagonal(f: Furniture) -> float:
    return 0.5 * math.hypot(f.dims[0], f.dims[1])


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
    half = _half_diagonal(f)
    p = np.array([f.x, f.y])
    if len(edges) and point_segment_distance(p, edges).min() < half + robot_radius_m + EDGE_CLEARANCE_M:
        return False
    if len(walls) and point_segment_distance(p, walls).min() < half + WALL_CLEARANCE_M:
        return False
    return not any(math.hypot(o.x - f.x, o.y - f.y) < half + _half_diagonal(o) + PIECE_GAP_M for o in placed)


def random_furniture(building: Building, n: int, rng: np.random.Generator, robot_radius_m: float) -> tuple[Furniture, ...]:
    """``n`` pieces of random kinds in the building's open areas (or rooms), clear of
    walls, of each other and of the navigation graph's edges."""
    if n == 0:
        return ()
    zones = building.furniture_zones
    if not zones:
        raise InputError("actors.random_furniture: the map has no open areas or rooms to place furniture in")
    edges = building.navgraph.edge_segments()
    walls = np.asarray(building.vectormap.segments)
    out: list[Furniture] = []
    for _ in range(TRIES_PER_PIECE * n):
        if len(out) == n:
            break
        f = draw_furniture(zones, rng)
        if furniture_fits(f, out, edges, walls, robot_radius_m):
            out.append(f)
    if len(out) < n:
        raise InputError(f"actors.random_furniture: only {len(out)} of {n} pieces fit in the map's open areas clear of the nav graph")
    return tuple(out)


def replace_furniture(
    building: Building, pieces: list[Furniture], fixed: int, rng: np.random.Generator, robot_radius_m: float, park: tuple[float, float]
) -> list[Furniture]:
    """New places for ``pieces[fixed:]`` (kinds kept), as :func:`random_furniture` places
    them; a piece that does not fit in ``TRIES_PER_PIECE`` tries is parked at ``park``
    (outside the building), offset 10 m per piece."""
    zones = building.furniture_zones
    edges = building.navgraph.edge_segments()
    walls = np.asarray(building.vectormap.segments)
    placed = list(pieces[:fixed])
    for k in range(fixed, len(pieces)):
        new = replace(pieces[k], x=park[0] - 10.0 * k, y=park[1])
        for _ in range(TRIES_PER_PIECE):
            f = draw_furniture(zones, rng, pieces[k].kind)
            if furniture_fits(f, placed, edges, walls, robot_radius_m):
                new = f
                break
        placed.append(new)
    return placed


def random_people(graph: NavGraph, n: int, rng: np.random.Generator) -> tuple[Person, ...]:
    """People walking back and forth along random shortest paths of the nav graph."""
    out = []
    ids = graph.node_ids()
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
