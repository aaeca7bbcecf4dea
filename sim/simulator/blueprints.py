"""Office-building blueprints: a vector map of thin walls, a matching nav graph, and zones.

A :class:`Blueprint` is what the simulator builds a world from: walls as 2D segments
(:class:`autonomy.maps.vectormap.VectorMap`), a UT AMRL-style navigation graph, and the boxes
of the offices, open areas (atria) and corridors, so scenarios can place furniture and
people.

:func:`generate_building` draws a seeded corridor-loop / grid office floor: a ring of
offices along the exterior walls, a corridor loop, and blocks of double-loaded offices
between internal corridors, some of them (partly) replaced by open atria with pillars.
Doorways are gaps in the walls. Nav-graph edges keep at least
``config.min_clearance_m`` from every wall. ``config.irregularity``
(:class:`~sim.simulator.irregular.Irregularity`, on by default) then makes the walls as
irregular as a hand-drawn map's: slightly skewed, corners jittered, door recesses, jogs,
broken and doubled lines.

Two fixed buildings ship in ``sim/assets`` (``python -m sim.simulator.blueprints`` regenerates
them): :func:`corridor_loop` (about 60 x 40 m) and :func:`small_floor` (16 x 10 m).
"""

from __future__ import annotations

import argparse
import json
import math
import os
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import WallIndex, segment_distances
from autonomy.maps.vectormap import (
    MapFormatError,
    NavEdge,
    NavGraph,
    NavNode,
    VectorMap,
    load_navgraph,
    load_vectormap,
    save_navgraph,
    save_vectormap,
)
from sim.simulator.irregular import Door, Irregularity, Piece, irregular_walls

__all__ = [
    "Box",
    "Blueprint",
    "BuildingConfig",
    "Irregularity",
    "generate_building",
    "corridor_loop",
    "small_floor",
    "SHIPPED",
    "ASSETS_DIR",
    "load_blueprint",
    "save_blueprint",
    "nav_edge_clearances",
    "segment_distances",
    "main",
]

Box = tuple[float, float, float, float]
"""Axis-aligned box ``(xmin, ymin, xmax, ymax)`` in metres."""

ASSETS_DIR = Path(__file__).resolve().parent.parent / "assets"
"""Where the shipped blueprints live."""

_DOOR_INNER_M = 0.75
"""Distance of the just-inside-the-door node from the door's wall."""
_DOOR_JAMB_MARGIN_M = 0.45
"""Extra distance from a door's edge to the room's side wall."""


def _q(x: float) -> float:
    """Quantise a coordinate to the millimetre (and turn -0.0 into 0.0)."""
    return round(float(x), 3) + 0.0


# --------------------------------------------------------------------------- Blueprint


@dataclass(frozen=True, eq=False)
class Blueprint:
    """A floor: walls, nav graph and zones (all in world metres)."""

    vectormap: VectorMap
    """Thin walls as line segments."""
    navgraph: NavGraph
    """Navigation graph; every edge keeps the robot clear of the walls."""
    rooms: tuple[Box, ...]
    """Office boxes (each reachable through a doorway)."""
    open_areas: tuple[Box, ...]
    """Atria / open spaces (furniture and people go here)."""
    corridors: tuple[Box, ...]
    """Corridor boxes (they overlap at junctions)."""
    name: str = ""
    """Blueprint name (the asset file stem)."""

    def extent(self) -> Box:
        """Bounding box of the walls."""
        return self.vectormap.extent()

    def __repr__(self) -> str:
        return (
            f"Blueprint(name={self.name!r}, n_segments={self.vectormap.n_segments}, "
            f"n_nodes={self.navgraph.n_nodes}, rooms={len(self.rooms)}, "
            f"open_areas={len(self.open_areas)}, corridors={len(self.corridors)})"
        )


# --------------------------------------------------------------------------- geometry checks


def nav_edge_clearances(bp: Blueprint, cutoff_m: float = 5.0) -> np.ndarray:
    """(E,) exact distance from each nav-graph edge to the nearest wall, capped at ``cutoff_m``."""
    return WallIndex(bp.vectormap.segments).clearances(bp.navgraph.edge_segments(), cutoff_m)


# --------------------------------------------------------------------------- builders


class _Walls:
    """Axis-aligned thin walls on lines, unioned per line, with door gaps cut out."""

    def __init__(self) -> None:
        self.h: dict[float, list[tuple[float, float]]] = defaultdict(list)
        self.v: dict[float, list[tuple[float, float]]] = defaultdict(list)
        self.gaps_h: dict[float, list[tuple[float, float]]] = defaultdict(list)
        self.gaps_v: dict[float, list[tuple[float, float]]] = defaultdict(list)
        self.extra: list[tuple[float, float, float, float]] = []
        self.doors: list[Door] = []

    @staticmethod
    def _add(store: dict[float, list[tuple[float, float]]], c: float, a: float, b: float) -> None:
        c, a, b = _q(c), _q(a), _q(b)
        if b < a:
            a, b = b, a
        if b > a:
            store[c].append((a, b))

    def hline(self, y: float, x0: float, x1: float) -> None:
        self._add(self.h, y, x0, x1)

    def vline(self, x: float, y0: float, y1: float) -> None:
        self._add(self.v, x, y0, y1)

    def gap_h(self, y: float, x0: float, x1: float) -> None:
        self._add(self.gaps_h, y, x0, x1)

    def gap_v(self, x: float, y0: float, y1: float) -> None:
        self._add(self.gaps_v, x, y0, y1)

    def rect(self, r: Box) -> None:
        x0, y0, x1, y1 = r
        self.hline(y0, x0, x1)
        self.hline(y1, x0, x1)
        self.vline(x0, y0, y1)
        self.vline(x1, y0, y1)

    def polygon(self, pts: Sequence[tuple[float, float]]) -> None:
        """A closed polygon of free-standing (non-axis-aligned allowed) segments."""
        n = len(pts)
        for i in range(n):
            (x0, y0), (x1, y1) = pts[i], pts[(i + 1) % n]
            self.extra.append((_q(x0), _q(y0), _q(x1), _q(y1)))

    @staticmethod
    def _pieces(
        ivs: list[tuple[float, float]], gaps: list[tuple[float, float]]
    ) -> list[tuple[float, float]]:
        merged: list[list[float]] = []
        for a, b in sorted(ivs):
            if merged and a <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        gaps = sorted(gaps)
        out: list[tuple[float, float]] = []
        for a, b in merged:
            cur = a
            for ga, gb in gaps:
                if gb <= cur or ga >= b:
                    continue
                if ga > cur:
                    out.append((cur, ga))
                cur = max(cur, gb)
            if b > cur:
                out.append((cur, b))
        return [(a, b) for a, b in out if b - a > 1e-6]

    @staticmethod
    def _split(a: float, b: float, max_seg: float | None) -> list[float]:
        if max_seg is None or b - a <= max_seg:
            return [a, b]
        n = math.ceil((b - a) / max_seg - 1e-9)
        pts = [a] + [_q(a + (b - a) * k / n) for k in range(1, n)] + [b]
        return pts

    def pieces(self) -> list[Piece]:
        """The unsplit walls in :meth:`build`'s order: horizontal lines by y, then vertical by x."""
        out: list[Piece] = []
        for y in sorted(self.h):
            out.extend((True, y, a, b) for a, b in self._pieces(self.h[y], self.gaps_h.get(y, [])))
        for x in sorted(self.v):
            out.extend((False, x, a, b) for a, b in self._pieces(self.v[x], self.gaps_v.get(x, [])))
        return out

    def build(self, max_segment_m: float | None) -> np.ndarray:
        rows: list[tuple[float, float, float, float]] = []
        for y in sorted(self.h):
            for a, b in self._pieces(self.h[y], self.gaps_h.get(y, [])):
                pts = self._split(a, b, max_segment_m)
                rows.extend((pts[k], y, pts[k + 1], y) for k in range(len(pts) - 1))
        for x in sorted(self.v):
            for a, b in self._pieces(self.v[x], self.gaps_v.get(x, [])):
                pts = self._split(a, b, max_segment_m)
                rows.extend((x, pts[k], x, pts[k + 1]) for k in range(len(pts) - 1))
        rows.extend(self.extra)
        return np.array(rows, dtype=np.float64).reshape(-1, 4)


class _Graph:
    """Nav-graph builder: nodes deduplicated by (mm-quantised) position."""

    def __init__(self) -> None:
        self.ids: dict[tuple[float, float], int] = {}
        self.nodes: list[NavNode] = []
        self.edges: dict[tuple[int, int], NavEdge] = {}

    def node(self, x: float, y: float) -> int:
        key = (_q(x), _q(y))
        nid = self.ids.get(key)
        if nid is None:
            nid = len(self.nodes)
            self.ids[key] = nid
            self.nodes.append(NavNode(nid, key[0], key[1]))
        return nid

    def edge(self, a: int, b: int, **kw: Any) -> None:
        if a == b:
            return
        key = (min(a, b), max(a, b))
        if key not in self.edges:
            self.edges[key] = NavEdge(a, b, **kw)

    def build(self) -> NavGraph:
        return NavGraph(tuple(self.nodes), tuple(self.edges.values()))


@dataclass
class _Corridor:
    """A straight corridor: its box and its centreline, with the stops that need nodes."""

    horizontal: bool
    box: Box
    lo: float
    hi: float
    stops: set[float] = field(default_factory=set)

    @property
    def c(self) -> float:
        """Centreline coordinate (y of a horizontal corridor, x of a vertical one)."""
        x0, y0, x1, y1 = self.box
        return _q((y0 + y1) / 2) if self.horizontal else _q((x0 + x1) / 2)

    @property
    def half_width(self) -> float:
        x0, y0, x1, y1 = self.box
        return (y1 - y0) / 2 if self.horizontal else (x1 - x0) / 2

    @property
    def span(self) -> tuple[float, float]:
        """Extent of the box along the corridor."""
        x0, y0, x1, y1 = self.box
        return (x0, x1) if self.horizontal else (y0, y1)

    def at(self, t: float) -> tuple[float, float]:
        """World point on the centreline at coordinate ``t`` along the corridor."""
        return (t, self.c) if self.horizontal else (self.c, t)

    def chain(self, g: _Graph, spacing_m: float) -> None:
        """Nodes at every stop (and at most ``spacing_m`` apart) joined along the centreline."""
        ts = sorted({_q(t) for t in self.stops} | {_q(self.lo), _q(self.hi)})
        full: list[float] = []
        for a, b in zip(ts[:-1], ts[1:], strict=True):
            full.append(a)
            n = math.ceil((b - a) / spacing_m - 1e-9)
            full.extend(_q(a + (b - a) * k / n) for k in range(1, n))
        full.append(ts[-1])
        ids = [g.node(*self.at(t)) for t in full]
        clearance = _q(self.half_width)
        for a, b in zip(ids[:-1], ids[1:], strict=True):
            g.edge(a, b, max_clearance=clearance)


def _door_centre(
    room: Box,
    side: str,
    corr: _Corridor,
    door_w: float,
    rng: np.random.Generator | None,
    door_t: float | None,
) -> float:
    """Where along its wall a room's door is centred: on the part of the wall that faces the
    corridor, clear of the jambs; ``door_t`` if given, else drawn near one end of that part
    (near its middle for a big room)."""
    x0, y0, x1, y1 = room
    m = door_w / 2 + _DOOR_JAMB_MARGIN_M
    along = (x0, x1) if side in "SN" else (y0, y1)
    s0, s1 = corr.span
    a, b = max(along[0], s0) + m, min(along[1], s1) - m
    if b < a:
        raise InputError(f"room {room} has no {door_w:.2f} m door on side {side} facing its corridor")
    if door_t is None:
        assert rng is not None
        u = float(rng.uniform(0.0, min(0.4, b - a)))
        door_t = a + u if rng.random() < 0.5 else b - u
        if along[1] - along[0] > 6.0:  # big rooms: door near the middle of the facing part
            door_t = (a + b) / 2 + float(rng.uniform(-0.5, 0.5)) * min(1.0, (b - a) / 2)
    return _q(min(max(door_t, a), b))


def _door_wall(room: Box, side: str) -> tuple[float, float]:
    """The coordinate of a room's wall on ``side`` and the direction into the room across it."""
    x0, y0, x1, y1 = room
    if side == "S":
        return y0, 1.0
    if side == "N":
        return y1, -1.0
    if side == "W":
        return x0, 1.0
    return x1, -1.0


def _add_room(
    walls: _Walls,
    g: _Graph,
    rooms: list[Box],
    room: Box,
    side: str,
    corr: _Corridor,
    door_w: float,
    rng: np.random.Generator | None = None,
    door_t: float | None = None,
) -> None:
    """A rectangular office with one door on ``side`` ('S', 'N', 'W', 'E') facing ``corr``.

    Nav nodes: the corridor centreline at the door, the doorway, just inside, the centre.
    """
    x0, y0, x1, y1 = room
    walls.rect(room)
    rooms.append(room)
    t = _door_centre(room, side, corr, door_w, rng, door_t)
    lo, hi = _q(t - door_w / 2), _q(t + door_w / 2)
    wall, inward = _door_wall(room, side)
    walls.doors.append((side in "SN", _q(wall), lo, hi, inward))
    if side in "SN":
        walls.gap_h(wall, lo, hi)
        pts = [(t, corr.c), (t, wall), (t, wall + inward * _DOOR_INNER_M)]
    else:
        walls.gap_v(wall, lo, hi)
        pts = [(corr.c, t), (wall, t), (wall + inward * _DOOR_INNER_M, t)]
    corr.stops.add(t)
    ids = [g.node(*p) for p in pts]
    centre = g.node((x0 + x1) / 2, (y0 + y1) / 2)
    half_door = _q(door_w / 2)
    g.edge(ids[0], ids[1], has_door=True, max_speed=0.5, max_clearance=half_door)
    g.edge(ids[1], ids[2], has_door=True, max_speed=0.5, max_clearance=half_door)
    g.edge(ids[2], centre, max_clearance=_q(min(x1 - x0, y1 - y0) / 2 - 0.5))


def _node_grid(g, xs, ys) -> list[list[int]]:
    """Nav nodes on a grid of xs x ys joined to their 4-neighbours (open areas)."""
    ids = [[g.node(x, y) for x in xs] for y in ys]
    for j in range(len(ys)):
        for i in range(len(xs)):
            if i + 1 < len(xs):
                g.edge(ids[j][i], ids[j][i + 1], max_clearance=1.0)
            if j + 1 < len(ys):
                g.edge(ids[j][i], ids[j + 1][i], max_clearance=1.0)
    return ids


def _add_open_area(
    walls: _Walls,
    g: _Graph,
    areas: list[Box],
    box: Box,
    connect: dict[str, _Corridor],
    spacing_m: float,
    inset_m: float,
    pillars: bool,
    pillar_size_m: float,
    pillar_sides: int,
) -> None:
    """An open area: a grid of nav nodes, optional pillars between them, and edges out to
    the corridors in ``connect`` (keyed by the side 'S', 'N', 'W', 'E' they lie on)."""
    x0, y0, x1, y1 = box
    areas.append(box)
    xs, ys = _grid_coords(x0, x1, inset_m, spacing_m), _grid_coords(y0, y1, inset_m, spacing_m)
    ids = _node_grid(g, xs, ys)
    _connect_area(g, ids, xs, ys, connect)
    if pillars and len(xs) >= 2 and len(ys) >= 2:
        _add_pillars(walls, xs, ys, pillar_size_m, pillar_sides)


def _grid_coords(a: float, b: float, inset_m: float, spacing_m: float) -> list[float]:
    """Evenly spaced coordinates about ``spacing_m`` apart from ``a + inset_m`` to ``b - inset_m``."""
    a, b = a + inset_m, b - inset_m
    if b - a < 1e-6:
        return [_q((a + b) / 2)]
    n = max(1, round((b - a) / spacing_m))
    return [_q(a + (b - a) * k / n) for k in range(n + 1)]


def _connect_area(
    g: _Graph, ids: list[list[int]], xs: list[float], ys: list[float], connect: dict[str, _Corridor]
) -> None:
    """Join the outer nodes of an area's grid straight across to the corridors in ``connect``."""
    for side, corr in sorted(connect.items()):
        if side in "SN":
            row = 0 if side == "S" else len(ys) - 1
            for i, x in enumerate(xs):
                corr.stops.add(x)
                g.edge(ids[row][i], g.node(x, corr.c), max_clearance=1.0)
        else:
            col = 0 if side == "W" else len(xs) - 1
            for j, y in enumerate(ys):
                corr.stops.add(y)
                g.edge(ids[j][col], g.node(corr.c, y), max_clearance=1.0)


def _add_pillars(walls: _Walls, xs: list[float], ys: list[float], pillar_size_m: float, pillar_sides: int) -> None:
    """A checkerboard of pillars in the cells of an area's node grid, where they leave the
    robot room to pass between the nodes."""
    h = pillar_size_m / 2
    r = h if pillar_sides == 4 else h / math.cos(math.pi / pillar_sides)  # polygon circumradius
    reach = h * math.sqrt(2) if pillar_sides == 4 else r
    for j in range(len(ys) - 1):
        for i in range(len(xs) - 1):
            if (i + j) % 2:
                continue  # a checkerboard of columns between the nav nodes
            cx, cy = (xs[i] + xs[i + 1]) / 2, (ys[j] + ys[j + 1]) / 2
            half_cell = min(xs[i + 1] - xs[i], ys[j + 1] - ys[j]) / 2
            if half_cell - reach < 0.6:
                continue
            if pillar_sides == 4:
                walls.rect((_q(cx - h), _q(cy - h), _q(cx + h), _q(cy + h)))
            else:
                a0 = math.pi / pillar_sides
                walls.polygon(
                    [
                        (cx + r * math.cos(a0 + 2 * math.pi * k / pillar_sides),
                         cy + r * math.sin(a0 + 2 * math.pi * k / pillar_sides))
                        for k in range(pillar_sides)
                    ]
                )


# --------------------------------------------------------------------------- generator


@dataclass(frozen=True)
class BuildingConfig:
    """Parameters of the procedural corridor-loop / grid office floor (metres)."""

    width_m: float = 60.0
    """Footprint size along x."""
    height_m: float = 40.0
    """Footprint size along y."""
    corridor_width_range_m: tuple[float, float] = (2.0, 2.5)
    """Width of each corridor, drawn per corridor."""
    outer_room_depth_range_m: tuple[float, float] = (4.0, 6.0)
    """Depth of the offices between the exterior walls and the corridor loop (per side)."""
    room_depth_range_m: tuple[float, float] = (4.0, 6.0)
    """Depth of the offices in the blocks inside the loop (per row)."""
    room_width_range_m: tuple[float, float] = (2.8, 4.5)
    """Width of an office along its corridor."""
    large_room_prob: float = 0.1
    """Chance that two neighbouring offices merge into one (meeting rooms)."""
    door_width_range_m: tuple[float, float] = (0.9, 1.0)
    """Doorway width."""
    block_width_m: float = 13.0
    """Target size of a block inside the loop along x (between vertical corridors)."""
    block_length_m: float = 26.0
    """Target size of a block inside the loop along y (between horizontal corridors)."""
    min_core_m: float = 2.0
    """A block deeper than two rows of offices plus this gets a closed service core."""
    core_partition_range_m: tuple[float, float] = (4.0, 8.0)
    """Spacing of the cross walls inside a service core."""
    n_atria: int = 1
    """Number of blocks that hold an open atrium."""
    atrium_length_range_m: tuple[float, float] = (11.0, 15.0)
    """A block longer than this (plus a row of offices) keeps offices beside its atrium."""
    atrium_node_spacing_m: float = 3.5
    """Spacing of the nav-node grid in an atrium."""
    atrium_pillars: bool = True
    """Put pillars between the atrium's nav nodes."""
    pillar_size_m: float = 0.5
    """Pillar width."""
    pillar_sides: int = 4
    """Pillar polygon sides (4: square, 8: octagonal 'round' column)."""
    pilaster_spacing_m: float | None = None
    """Spacing of structural pilasters (jogs) along the exterior walls; None for none."""
    node_spacing_m: float = 3.0
    """Largest gap between nav nodes along a corridor."""
    max_segment_m: float | None = None
    """Split walls into pieces at most this long (as mapped walls are; collinear unless
    ``irregularity`` bends them slightly at the breaks)."""
    min_clearance_m: float = 0.35
    """Nav edges keep at least this from every wall (robot radius 0.3 m plus margin)."""
    irregularity: Irregularity = Irregularity()
    """How far the walls depart from an exact square drawing, as in a hand-drawn map;
    ``Irregularity.none()`` keeps them exactly axis-aligned."""
    name: str = "generated"
    """Blueprint name."""

    def __post_init__(self) -> None:
        def bad(name: str, what: str) -> InputError:
            return InputError(f"BuildingConfig.{name}: expected {what}, got {getattr(self, name)!r}")

        for name in (
            "corridor_width_range_m",
            "outer_room_depth_range_m",
            "room_depth_range_m",
            "room_width_range_m",
            "door_width_range_m",
            "core_partition_range_m",
            "atrium_length_range_m",
        ):
            v = getattr(self, name)
            if not (len(v) == 2 and 0 < v[0] <= v[1] and math.isfinite(v[1])):
                raise bad(name, "a range (lo, hi) with 0 < lo <= hi")
        for name in ("width_m", "height_m", "block_width_m", "block_length_m", "pillar_size_m",
                     "node_spacing_m", "atrium_node_spacing_m", "min_core_m"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise bad(name, "a positive number")
        if self.max_segment_m is not None and not self.max_segment_m > 0:
            raise bad("max_segment_m", "None or a positive number")
        if self.pilaster_spacing_m is not None and not self.pilaster_spacing_m >= 2.0:
            raise bad("pilaster_spacing_m", "None or a number >= 2.0")
        if not 0 <= self.large_room_prob <= 1:
            raise bad("large_room_prob", "a probability in [0, 1]")
        if self.n_atria < 0:
            raise bad("n_atria", "an integer >= 0")
        if self.pillar_sides < 3:
            raise bad("pillar_sides", "an integer >= 3")
        if not isinstance(self.irregularity, Irregularity):
            raise bad("irregularity", "an Irregularity (Irregularity.none() for exact walls)")
        if self.corridor_width_range_m[0] / 2 < self.min_clearance_m + 0.3:
            raise bad("corridor_width_range_m", f"corridors at least {2 * (self.min_clearance_m + 0.3):.2f} m wide")
        if self.door_width_range_m[0] / 2 < self.min_clearance_m:
            raise bad("door_width_range_m", f"doors at least {2 * self.min_clearance_m:.2f} m wide")
        need = self.door_width_range_m[1] + 2 * _DOOR_JAMB_MARGIN_M + 0.2
        if self.room_width_range_m[0] < need:
            raise bad("room_width_range_m", f"rooms at least {need:.2f} m wide (door plus jambs)")
        if self.room_depth_range_m[0] < 2 * _DOOR_INNER_M + 0.5 or self.outer_room_depth_range_m[0] < 2 * _DOOR_INNER_M + 0.5:
            raise bad("room_depth_range_m", f"rooms at least {2 * _DOOR_INNER_M + 0.5:.2f} m deep")
        inner_w = self.width_m - 2 * (self.outer_room_depth_range_m[1] + self.corridor_width_range_m[1])
        inner_h = self.height_m - 2 * (self.outer_room_depth_range_m[1] + self.corridor_width_range_m[1])
        if min(inner_w, inner_h) < self.room_depth_range_m[0]:
            raise InputError(
                f"BuildingConfig: a {self.width_m} x {self.height_m} m footprint leaves no room inside "
                "the corridor loop; make it larger or the outer offices / corridors smaller"
            )

    @classmethod
    def large(cls, **overrides: Any) -> BuildingConfig:
        """A realistic 100 x 100 m floor of about 9,000+ wall segments (real mapped buildings
        hold 1,000-9,000): fine collinear wall pieces, exterior pilasters, octagonal pillars."""
        base = cls(
            width_m=100.0,
            height_m=100.0,
            n_atria=3,
            block_width_m=14.0,
            block_length_m=28.0,
            pillar_sides=8,
            pilaster_spacing_m=4.0,
            max_segment_m=0.4,
            name="large_floor",
        )
        return replace(base, **overrides)


def _partition(
    length: float, wmin: float, wmax: float, merge_prob: float, rng: np.random.Generator
) -> list[float]:
    """Cut ``length`` into office widths (>= wmin unless the whole is shorter); returns the
    interior cut offsets from 0, quantised."""
    if length < 2 * wmin:
        return []
    n_max = math.floor(length / wmin)
    n = min(n_max, max(1, round(length / ((wmin + wmax) / 2))))
    w = rng.uniform(0.6, 1.4, n)
    widths = wmin + (length - n * wmin) * w / w.sum()
    merged: list[float] = []
    i = 0
    while i < n:
        if i + 1 < n and rng.random() < merge_prob:
            merged.append(float(widths[i] + widths[i + 1]))
            i += 2
        else:
            merged.append(float(widths[i]))
            i += 1
    cuts = np.cumsum(merged)[:-1]
    return [_q(c) for c in cuts]


def _split_range(
    lo: float, hi: float, n: int, gaps: Sequence[float], rng: np.random.Generator
) -> list[tuple[float, float]]:
    """Split [lo, hi] into n jittered parts separated by the given gap widths."""
    avail = hi - lo - sum(gaps)
    w = rng.uniform(0.85, 1.15, n)
    sizes = avail * w / w.sum()
    out = []
    t = lo
    for k in range(n):
        a = _q(t)
        t += sizes[k]
        b = _q(t) if k < n - 1 else _q(hi)
        out.append((a, b))
        if k < n - 1:
            t = b + gaps[k]
    return out


def _n_blocks(length: float, block_m: float, cfg: BuildingConfig) -> int:
    """How many blocks of about ``block_m`` (with corridors between them) fit in ``length``,
    each still deep enough for two rows of offices."""
    cw_mean = sum(cfg.corridor_width_range_m) / 2
    dmin = cfg.room_depth_range_m[0]
    n = max(1, round((length + cw_mean) / (block_m + cw_mean)))
    while n > 1 and (length - (n - 1) * cfg.corridor_width_range_m[1]) / n * 0.85 < 2 * dmin:
        n -= 1
    return n


def _block_box(vertical: bool, ua: float, ub: float, va: float, vb: float) -> Box:
    """A box from its span ``ua..ub`` along a block's rows and ``va..vb`` across them."""
    return (va, ua, vb, ub) if vertical else (ua, va, ub, vb)


def _block_facing(box: Box, side_c: dict[str, _Corridor]) -> tuple[bool, _Corridor, _Corridor]:
    """Whether a block's office rows run along y (facing its W and E corridors) rather than
    along x (facing S and N), and those two corridors, low side first."""
    x0, y0, x1, y1 = box
    vertical = (y1 - y0) >= (x1 - x0)
    if vertical:
        return vertical, side_c["W"], side_c["E"]
    return vertical, side_c["S"], side_c["N"]


def _cut_atrium(box: Box, vertical: bool, a_len: float, at_low: bool) -> tuple[Box, Box, str]:
    """Split a block into an atrium ``a_len`` long at its low or high end and the rest;
    also the side of the atrium that the rest closes off."""
    x0, y0, x1, y1 = box
    if vertical:
        cut = _q(y0 + a_len) if at_low else _q(y1 - a_len)
        lo, hi = (x0, y0, x1, cut), (x0, cut, x1, y1)
        return (lo, hi, "N") if at_low else (hi, lo, "S")
    cut = _q(x0 + a_len) if at_low else _q(x1 - a_len)
    lo, hi = (x0, y0, cut, y1), (cut, y0, x1, y1)
    return (lo, hi, "E") if at_low else (hi, lo, "W")


def _assemble(
    walls: _Walls,
    g: _Graph,
    rooms: list[Box],
    areas: list[Box],
    corridors: Sequence[Box],
    max_segment_m: float | None,
    name: str,
    segments: np.ndarray | None = None,
) -> Blueprint:
    """The finished :class:`Blueprint` from the builders and the zone lists (``segments``,
    if given, instead of the walls' own)."""
    return Blueprint(
        vectormap=VectorMap(walls.build(max_segment_m) if segments is None else segments, name=name),
        navgraph=g.build(),
        rooms=tuple(rooms),
        open_areas=tuple(areas),
        corridors=tuple(corridors),
        name=name,
    )


@dataclass
class _Grid:
    """The corridors of a drawn floor: the loop and the internal corridors between blocks."""

    depth: dict[str, float]
    """Depth of the outer offices on each side ('S', 'N', 'W', 'E')."""
    cols: list[tuple[float, float]]
    """x span of each column of blocks inside the loop."""
    rows: list[tuple[float, float]]
    """y span of each row of blocks inside the loop."""
    vcorrs: list[_Corridor]
    """Vertical corridors west to east (the loop's west side first, its east side last)."""
    hcorrs: list[_Corridor]
    """Horizontal corridors south to north (the loop's south side first, its north side last)."""


class _Floor:
    """One floor being drawn: its config, random stream, walls, nav graph and zones.

    The methods draw from ``rng`` in a fixed order, so a config and a seed give one floor.
    """

    def __init__(self, cfg: BuildingConfig, rng: np.random.Generator) -> None:
        self.cfg, self.rng = cfg, rng
        self.walls, self.g = _Walls(), _Graph()
        self.rooms: list[Box] = []
        self.areas: list[Box] = []
        self.W, self.H = _q(cfg.width_m), _q(cfg.height_m)

    def uni(self, r: tuple[float, float]) -> float:
        """One uniform draw from the range ``r``, quantised."""
        return _q(self.rng.uniform(r[0], r[1]))

    def room(self, box: Box, door_side: str, corr: _Corridor) -> None:
        """An office with a door of drawn width on ``door_side``, facing ``corr``."""
        door_w = self.uni(self.cfg.door_width_range_m)
        _add_room(self.walls, self.g, self.rooms, box, door_side, corr, door_w, self.rng)

    def draw_grid(self) -> _Grid:
        """The corridor loop inside the outer offices, and the corridors between the blocks."""
        cfg, W, H = self.cfg, self.W, self.H
        d_b, d_t, d_l, d_r = (self.uni(cfg.outer_room_depth_range_m) for _ in range(4))
        cw_b, cw_t, cw_l, cw_r = (self.uni(cfg.corridor_width_range_m) for _ in range(4))
        ix0, ix1 = _q(d_l + cw_l), _q(W - d_r - cw_r)
        iy0, iy1 = _q(d_b + cw_b), _q(H - d_t - cw_t)
        left = _Corridor(False, (d_l, d_b, ix0, _q(H - d_t)), 0.0, 0.0)
        right = _Corridor(False, (ix1, d_b, _q(W - d_r), _q(H - d_t)), 0.0, 0.0)
        bottom = _Corridor(True, (d_l, d_b, _q(W - d_r), iy0), left.c, right.c)
        top = _Corridor(True, (d_l, iy1, _q(W - d_r), _q(H - d_t)), left.c, right.c)
        left.lo, left.hi = bottom.c, top.c
        right.lo, right.hi = bottom.c, top.c
        n_cols = _n_blocks(ix1 - ix0, cfg.block_width_m, cfg)
        n_rows = _n_blocks(iy1 - iy0, cfg.block_length_m, cfg)
        vgaps = [self.uni(cfg.corridor_width_range_m) for _ in range(n_cols - 1)]
        hgaps = [self.uni(cfg.corridor_width_range_m) for _ in range(n_rows - 1)]
        cols = _split_range(ix0, ix1, n_cols, vgaps, self.rng)
        rows = _split_range(iy0, iy1, n_rows, hgaps, self.rng)
        inner_v = [
            _Corridor(False, (cols[k][1], iy0, cols[k + 1][0], iy1), bottom.c, top.c) for k in range(n_cols - 1)
        ]
        inner_h = [
            _Corridor(True, (ix0, rows[k][1], ix1, rows[k + 1][0]), left.c, right.c) for k in range(n_rows - 1)
        ]
        vcorrs, hcorrs = [left, *inner_v, right], [bottom, *inner_h, top]
        for vc in vcorrs:
            for hc in hcorrs:
                vc.stops.add(hc.c)
                hc.stops.add(vc.c)
        depth = {"S": d_b, "N": d_t, "W": d_l, "E": d_r}
        return _Grid(depth, cols, rows, vcorrs, hcorrs)

    def add_outer_ring(self, grid: _Grid) -> dict[str, list[float]]:
        """Offices along the exterior walls, each facing the loop (corner offices take the
        corners), and the exterior walls; returns the room joints along each side."""
        cfg, W, H, d = self.cfg, self.W, self.H, grid.depth
        wmin, wmax = cfg.room_width_range_m
        joints: dict[str, list[float]] = {}
        for side in "SNWE":
            lo, hi = (d["W"], _q(W - d["E"])) if side in "SN" else (d["S"], _q(H - d["N"]))
            cuts = [_q(lo + c) for c in _partition(hi - lo, wmin, wmax, cfg.large_room_prob, self.rng)]
            bounds = [0.0, *cuts, W] if side in "SN" else [lo, *cuts, hi]
            joints[side] = bounds
            for a, b in zip(bounds[:-1], bounds[1:], strict=True):
                self.room(*self._outer_room(grid, side, a, b))
        self.walls.rect((0.0, 0.0, W, H))
        return joints

    def _outer_room(self, grid: _Grid, side: str, a: float, b: float) -> tuple[Box, str, _Corridor]:
        """The box of an outer office spanning ``a..b`` on ``side``, its door side and corridor."""
        W, H, d = self.W, self.H, grid.depth
        if side == "S":
            return (a, 0.0, b, d["S"]), "N", grid.hcorrs[0]
        if side == "N":
            return (a, _q(H - d["N"]), b, H), "S", grid.hcorrs[-1]
        if side == "W":
            return (0.0, a, d["W"], b), "E", grid.vcorrs[0]
        return (_q(W - d["E"]), a, W, b), "W", grid.vcorrs[-1]

    def add_blocks(self, grid: _Grid) -> None:
        """The blocks inside the loop: offices back to back facing the corridors on their
        long sides, ``n_atria`` of them (drawn) holding an open atrium instead."""
        n_cols, n_rows = len(grid.cols), len(grid.rows)
        n_blocks = n_cols * n_rows
        n_atria = self.cfg.n_atria
        if n_atria > n_blocks:
            raise InputError(
                f"BuildingConfig.n_atria: {n_atria} atria do not fit in {n_blocks} blocks inside the loop"
            )
        atria = set(self.rng.choice(n_blocks, size=n_atria, replace=False).tolist()) if n_atria else set()
        for j in range(n_rows):
            for i in range(n_cols):
                box = (grid.cols[i][0], grid.rows[j][0], grid.cols[i][1], grid.rows[j][1])
                side_c = {"W": grid.vcorrs[i], "E": grid.vcorrs[i + 1], "S": grid.hcorrs[j], "N": grid.hcorrs[j + 1]}
                if j * n_cols + i in atria:
                    self.add_atrium_block(box, side_c)
                else:
                    self.fill_rooms(box, *_block_facing(box, side_c))

    def fill_rooms(self, box: Box, vertical: bool, lo_c: _Corridor, hi_c: _Corridor) -> None:
        """Offices in ``box``: rows along y facing W/E corridors (vertical) or along x facing S/N."""
        x0, y0, x1, y1 = box
        v0, v1, u0, u1 = (x0, x1, y0, y1) if vertical else (y0, y1, x0, x1)
        lo_side, hi_side = ("W", "E") if vertical else ("S", "N")
        if v1 - v0 < 2 * self.cfg.room_depth_range_m[0]:
            row_specs = [(v0, v1, lo_c, lo_side)]
        else:
            da, db = self._row_depths(vertical, u0, u1, v0, v1)
            row_specs = [(v0, _q(v0 + da), lo_c, lo_side), (_q(v1 - db), v1, hi_c, hi_side)]
        wmin, wmax = self.cfg.room_width_range_m
        for va, vb, corr, dside in row_specs:
            cuts = _partition(u1 - u0, wmin, wmax, self.cfg.large_room_prob, self.rng)
            bounds = [u0] + [_q(u0 + c) for c in cuts] + [u1]
            for a, b in zip(bounds[:-1], bounds[1:], strict=True):
                self.room(_block_box(vertical, a, b, va, vb), dside, corr)

    def _row_depths(self, vertical: bool, u0: float, u1: float, v0: float, v1: float) -> tuple[float, float]:
        """Depths of a block's two office rows; a block deeper than two rows plus
        ``min_core_m`` gets a closed service core between them."""
        cfg = self.cfg
        span = v1 - v0
        if span <= 2 * cfg.room_depth_range_m[1] + cfg.min_core_m:
            da = _q(span * self.rng.uniform(0.45, 0.55))
            return da, _q(span - da)
        da, db = self.uni(cfg.room_depth_range_m), self.uni(cfg.room_depth_range_m)
        self._add_core(_block_box(vertical, u0, u1, _q(v0 + da), _q(v1 - db)), vertical, u0, u1)
        return da, db

    def _add_core(self, core: Box, vertical: bool, u0: float, u1: float) -> None:
        """A closed service core, cut by cross walls at drawn ``core_partition_range_m`` steps."""
        self.walls.rect(core)
        t = u0 + self.uni(self.cfg.core_partition_range_m)
        while t < u1 - 2.0:
            if vertical:
                self.walls.hline(t, core[0], core[2])
            else:
                self.walls.vline(t, core[1], core[3])
            t += self.uni(self.cfg.core_partition_range_m)

    def add_atrium_block(self, box: Box, side_c: dict[str, _Corridor]) -> None:
        """A block holding an open atrium joined to the corridors round it; a block long
        enough keeps a row of offices beside the atrium (the atrium then opens on three sides)."""
        cfg = self.cfg
        vertical, lo_c, hi_c = _block_facing(box, side_c)
        x0, y0, x1, y1 = box
        long_len = (y1 - y0) if vertical else (x1 - x0)
        a_len = self.uni(cfg.atrium_length_range_m)
        connect = dict(side_c)
        abox = box
        if long_len - a_len >= 2 * cfg.room_width_range_m[0] + 1.0:
            abox, rbox, closed = _cut_atrium(box, vertical, a_len, self.rng.random() < 0.5)
            connect.pop(closed)
            self.fill_rooms(rbox, vertical, lo_c, hi_c)
        _add_open_area(
            self.walls, self.g, self.areas, abox, connect, cfg.atrium_node_spacing_m, 1.25,
            cfg.atrium_pillars, cfg.pillar_size_m, cfg.pillar_sides,
        )


def generate_building(config: BuildingConfig, rng: np.random.Generator | int) -> Blueprint:
    """Draw a corridor-loop / grid office floor (same config and seed -> same floor)."""
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng(rng)
    floor = _Floor(config, rng)
    grid = floor.draw_grid()
    joints = floor.add_outer_ring(grid)
    floor.add_blocks(grid)
    if config.pilaster_spacing_m is not None:
        _add_pilasters(floor.walls, floor.W, floor.H, joints, config.pilaster_spacing_m)
    corridors = grid.vcorrs + grid.hcorrs
    for corr in corridors:
        corr.chain(floor.g, config.node_spacing_m)
    segments = None
    if config.irregularity.active:  # drawn after the layout: the same seed, the same layout
        w = floor.walls
        segments = irregular_walls(
            w.pieces(), np.array(w.extra, dtype=np.float64).reshape(-1, 4), w.doors,
            floor.g.build().edge_segments(), config.irregularity, rng, config.min_clearance_m,
            config.max_segment_m,
        )
    return _assemble(
        floor.walls, floor.g, floor.rooms, floor.areas, [c.box for c in corridors], config.max_segment_m,
        config.name, segments,
    )


def _add_pilasters(
    walls: _Walls, W: float, H: float, joints: dict[str, list[float]], spacing: float
) -> None:
    """Pilasters (0.4 m wide, 0.3 m deep jogs) along the inside of the exterior walls."""
    half, depth = 0.2, 0.3
    for side in "SNWE":
        length = W if side in "SN" else H
        js = list(joints[side]) + [0.0, length]
        t = spacing / 2
        while t < length:
            p = _q(t)
            t += spacing
            if min(abs(p - j) for j in js) < half + 0.6:
                continue
            a, b = _q(p - half), _q(p + half)
            if side == "S":
                walls.gap_h(0.0, a, b)
                walls.hline(depth, a, b)
                walls.vline(a, 0.0, depth)
                walls.vline(b, 0.0, depth)
            elif side == "N":
                walls.gap_h(H, a, b)
                walls.hline(_q(H - depth), a, b)
                walls.vline(a, _q(H - depth), H)
                walls.vline(b, _q(H - depth), H)
            elif side == "W":
                walls.gap_v(0.0, a, b)
                walls.vline(depth, a, b)
                walls.hline(a, 0.0, depth)
                walls.hline(b, 0.0, depth)
            else:
                walls.gap_v(W, a, b)
                walls.vline(_q(W - depth), a, b)
                walls.hline(a, _q(W - depth), W)
                walls.hline(b, _q(W - depth), W)


# --------------------------------------------------------------------------- shipped floors


def corridor_loop() -> Blueprint:
    """About 60 x 40 m: a corridor loop, offices inside and outside it, and an atrium."""
    cfg = BuildingConfig(
        width_m=60.0,
        height_m=40.0,
        n_atria=1,
        block_width_m=13.0,
        block_length_m=26.0,
        atrium_length_range_m=(12.0, 14.0),
        max_segment_m=1.0,
        irregularity=Irregularity.none(),  # the shipped file stays as it is
        name="corridor_loop",
    )
    return generate_building(cfg, 7)


def small_floor() -> Blueprint:
    """16 x 10 m: a short corridor, four offices and a small open area with a pillar."""
    walls, g = _Walls(), _Graph()
    rooms: list[Box] = []
    areas: list[Box] = []
    corr = _Corridor(True, (0.0, 4.0, 10.0, 6.2), 1.1, 10.0)
    walls.rect((0.0, 0.0, 16.0, 10.0))
    _add_room(walls, g, rooms, (0.0, 6.2, 5.0, 10.0), "S", corr, 0.95, door_t=3.9)
    _add_room(walls, g, rooms, (5.0, 6.2, 10.0, 10.0), "S", corr, 0.95, door_t=6.2)
    _add_room(walls, g, rooms, (0.0, 0.0, 5.5, 4.0), "N", corr, 0.95, door_t=4.2)
    _add_room(walls, g, rooms, (5.5, 0.0, 10.0, 4.0), "N", corr, 0.95, door_t=6.8)
    box = (10.0, 0.0, 16.0, 10.0)
    areas.append(box)
    xs, ys = (11.5, 14.5), (1.5, 5.1, 8.5)
    ids = _node_grid(g, xs, ys)
    corr.chain(g, 3.0)
    g.edge(g.node(10.0, 5.1), ids[1][0], max_clearance=1.0)
    walls.rect((12.8, 3.1, 13.2, 3.5))  # one pillar between the open area's nodes
    return _assemble(walls, g, rooms, areas, [corr.box], 2.0, "small_floor")


SHIPPED = {"corridor_loop": corridor_loop, "small_floor": small_floor}
"""The shipped blueprints by name (their files live in :data:`ASSETS_DIR`)."""


# --------------------------------------------------------------------------- files

_VM_SUFFIX = ".vectormap.txt"
_NAV_SUFFIX = ".navigation.json"
_ZONES_SUFFIX = ".zones.json"
_ZONE_KEYS = ("rooms", "open_areas", "corridors")


def _stem(path: str | os.PathLike[str]) -> str:
    s = os.fspath(path)
    for suf in (_VM_SUFFIX, _NAV_SUFFIX, _ZONES_SUFFIX):
        if s.endswith(suf):
            return s[: -len(suf)]
    return s


def _format_zones(bp: Blueprint) -> str:
    def boxes(bs: tuple[Box, ...]) -> str:
        if not bs:
            return "[]"
        return "[\n    " + ",\n    ".join(json.dumps([float(v) for v in b]) for b in bs) + "\n  ]"

    parts = [f'  "name": {json.dumps(bp.name)}'] + [
        f'  "{k}": {boxes(getattr(bp, k))}' for k in _ZONE_KEYS
    ]
    return "{\n" + ",\n".join(parts) + "\n}\n"


def _parse_zones(text: str, source: str) -> tuple[str, dict[str, tuple[Box, ...]]]:
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise MapFormatError(f"{source}:{e.lineno}:{e.colno}: invalid JSON: {e.msg}", source=source, line=e.lineno) from None
    if not isinstance(data, dict):
        raise MapFormatError(f'{source}: expected an object {{"name", "rooms", "open_areas", "corridors"}}', source=source)
    name = data.get("name", "")
    if not isinstance(name, str):
        raise MapFormatError(f"{source}: name: expected a string, got {name!r}", source=source)
    out: dict[str, tuple[Box, ...]] = {}
    for k in _ZONE_KEYS:
        v = data.get(k, [])
        if not isinstance(v, list):
            raise MapFormatError(f"{source}: {k}: expected an array of boxes, got {v!r}", source=source)
        boxes = []
        for i, b in enumerate(v):
            ok = (
                isinstance(b, list)
                and len(b) == 4
                and all(isinstance(c, int | float) and not isinstance(c, bool) and math.isfinite(c) for c in b)
            )
            if not ok or not (b[0] <= b[2] and b[1] <= b[3]):
                raise MapFormatError(
                    f"{source}: {k}[{i}]: expected a box [xmin, ymin, xmax, ymax] of finite numbers, got {b!r}",
                    source=source,
                )
            boxes.append(tuple(float(c) for c in b))
        out[k] = tuple(boxes)
    return name, out


def save_blueprint(bp: Blueprint, stem_path: str | os.PathLike[str]) -> list[Path]:
    """Write ``<stem>.vectormap.txt``, ``<stem>.navigation.json`` and ``<stem>.zones.json``."""
    stem = _stem(stem_path)
    Path(stem).parent.mkdir(parents=True, exist_ok=True)
    vm = save_vectormap(bp.vectormap, stem + _VM_SUFFIX)
    nav = save_navgraph(bp.navgraph, stem + _NAV_SUFFIX)
    zones = Path(stem + _ZONES_SUFFIX)
    zones.write_text(_format_zones(bp), encoding="utf-8")
    return [vm, nav, zones]


def load_blueprint(stem_path: str | os.PathLike[str]) -> Blueprint:
    """Read a blueprint back from its three files (``stem_path`` may name any of them).

    A bare shipped name (``"corridor_loop"``) is looked up in :data:`ASSETS_DIR`.
    """
    stem = _stem(stem_path)
    if os.sep not in stem and "/" not in stem and not Path(stem + _VM_SUFFIX).exists():
        if Path(ASSETS_DIR / (stem + _VM_SUFFIX)).exists():
            stem = str(ASSETS_DIR / stem)
    vm = load_vectormap(stem + _VM_SUFFIX)
    nav = load_navgraph(stem + _NAV_SUFFIX)
    zpath = stem + _ZONES_SUFFIX
    try:
        text = Path(zpath).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MapFormatError(f"{zpath}: file not found", source=zpath) from None
    name, zones = _parse_zones(text, zpath)
    name = name or Path(stem).name
    return Blueprint(
        vectormap=VectorMap(vm.segments, name=name),
        navgraph=nav,
        rooms=zones["rooms"],
        open_areas=zones["open_areas"],
        corridors=zones["corridors"],
        name=name,
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Regenerate the shipped blueprints' files (``python -m sim.simulator.blueprints``)."""
    ap = argparse.ArgumentParser(prog="python -m sim.simulator.blueprints", description=main.__doc__)
    ap.add_argument("--out", type=Path, default=ASSETS_DIR, help="output directory (default: sim/assets)")
    args = ap.parse_args(argv)
    for name, fn in SHIPPED.items():
        bp = fn()
        paths = save_blueprint(bp, args.out / name)
        x0, y0, x1, y1 = bp.extent()
        print(
            f"{name}: {bp.vectormap.n_segments} segments, {x1 - x0:.1f} x {y1 - y0:.1f} m, "
            f"{bp.navgraph.n_nodes} nodes, {bp.navgraph.n_edges} edges, {len(bp.rooms)} rooms -> "
            + ", ".join(str(p) for p in paths)
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
