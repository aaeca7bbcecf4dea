"""A floor plan and the parts a floor is drawn from.

:class:`Blueprint` is what the simulator builds a world from: walls as 2D segments
(:class:`autonomy.maps.vectormap.VectorMap`), a UT AMRL-style navigation graph, and the boxes
of the offices, open areas (atria) and corridors, so scenarios can place furniture and
people.

The drawing parts here (:class:`Walls`, :class:`NavGraphBuilder`, :class:`Corridor`,
:func:`add_room`, :func:`add_open_area`, :func:`assemble`) are shared by the procedural
generator (:mod:`sim.simulator.floor_generator`) and the fixed shipped floors
(:mod:`sim.simulator.blueprints`). Doorways are gaps in the walls; every coordinate is
quantised to the millimetre.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import WallIndex
from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
from autonomy.maps.vectormap import VectorMap
from sim.simulator.irregular import Door, Piece

Box = tuple[float, float, float, float]
"""Axis-aligned box ``(xmin, ymin, xmax, ymax)`` in metres."""

DOOR_INNER_M = 0.75
"""Distance of the just-inside-the-door node from the door's wall."""
DOOR_JAMB_MARGIN_M = 0.45
"""Extra distance from a door's edge to the room's side wall."""


def quantise(x: float) -> float:
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


class Walls:
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
        c, a, b = quantise(c), quantise(a), quantise(b)
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
            self.extra.append((quantise(x0), quantise(y0), quantise(x1), quantise(y1)))

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
        pts = [a] + [quantise(a + (b - a) * k / n) for k in range(1, n)] + [b]
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


class NavGraphBuilder:
    """Nav-graph builder: nodes deduplicated by (mm-quantised) position."""

    def __init__(self) -> None:
        self.ids: dict[tuple[float, float], int] = {}
        self.nodes: list[NavNode] = []
        self.edges: dict[tuple[int, int], NavEdge] = {}

    def node(self, x: float, y: float) -> int:
        key = (quantise(x), quantise(y))
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
class Corridor:
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
        return quantise((y0 + y1) / 2) if self.horizontal else quantise((x0 + x1) / 2)

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

    def chain(self, g: NavGraphBuilder, spacing_m: float) -> None:
        """Nodes at every stop (and at most ``spacing_m`` apart) joined along the centreline."""
        ts = sorted({quantise(t) for t in self.stops} | {quantise(self.lo), quantise(self.hi)})
        full: list[float] = []
        for a, b in zip(ts[:-1], ts[1:], strict=True):
            full.append(a)
            n = math.ceil((b - a) / spacing_m - 1e-9)
            full.extend(quantise(a + (b - a) * k / n) for k in range(1, n))
        full.append(ts[-1])
        ids = [g.node(*self.at(t)) for t in full]
        clearance = quantise(self.half_width)
        for a, b in zip(ids[:-1], ids[1:], strict=True):
            g.edge(a, b, max_clearance=clearance)


def _door_centre(
    room: Box,
    side: str,
    corr: Corridor,
    door_w: float,
    rng: np.random.Generator | None,
    door_t: float | None,
) -> float:
    """Where along its wall a room's door is centred: on the part of the wall that faces the
    corridor, clear of the jambs; ``door_t`` if given, else drawn near one end of that part
    (near its middle for a big room)."""
    x0, y0, x1, y1 = room
    m = door_w / 2 + DOOR_JAMB_MARGIN_M
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
    return quantise(min(max(door_t, a), b))


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


def add_room(
    walls: Walls,
    g: NavGraphBuilder,
    rooms: list[Box],
    room: Box,
    side: str,
    corr: Corridor,
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
    lo, hi = quantise(t - door_w / 2), quantise(t + door_w / 2)
    wall, inward = _door_wall(room, side)
    walls.doors.append((side in "SN", quantise(wall), lo, hi, inward))
    if side in "SN":
        walls.gap_h(wall, lo, hi)
        pts = [(t, corr.c), (t, wall), (t, wall + inward * DOOR_INNER_M)]
    else:
        walls.gap_v(wall, lo, hi)
        pts = [(corr.c, t), (wall, t), (wall + inward * DOOR_INNER_M, t)]
    corr.stops.add(t)
    ids = [g.node(*p) for p in pts]
    centre = g.node((x0 + x1) / 2, (y0 + y1) / 2)
    half_door = quantise(door_w / 2)
    g.edge(ids[0], ids[1], has_door=True, max_speed=0.5, max_clearance=half_door)
    g.edge(ids[1], ids[2], has_door=True, max_speed=0.5, max_clearance=half_door)
    g.edge(ids[2], centre, max_clearance=quantise(min(x1 - x0, y1 - y0) / 2 - 0.5))


def node_grid(g, xs, ys) -> list[list[int]]:
    """Nav nodes on a grid of xs x ys joined to their 4-neighbours (open areas)."""
    ids = [[g.node(x, y) for x in xs] for y in ys]
    for j in range(len(ys)):
        for i in range(len(xs)):
            if i + 1 < len(xs):
                g.edge(ids[j][i], ids[j][i + 1], max_clearance=1.0)
            if j + 1 < len(ys):
                g.edge(ids[j][i], ids[j + 1][i], max_clearance=1.0)
    return ids


def add_open_area(
    walls: Walls,
    g: NavGraphBuilder,
    areas: list[Box],
    box: Box,
    connect: dict[str, Corridor],
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
    ids = node_grid(g, xs, ys)
    _connect_area(g, ids, xs, ys, connect)
    if pillars and len(xs) >= 2 and len(ys) >= 2:
        _add_pillars(walls, xs, ys, pillar_size_m, pillar_sides)


def _grid_coords(a: float, b: float, inset_m: float, spacing_m: float) -> list[float]:
    """Evenly spaced coordinates about ``spacing_m`` apart from ``a + inset_m`` to ``b - inset_m``."""
    a, b = a + inset_m, b - inset_m
    if b - a < 1e-6:
        return [quantise((a + b) / 2)]
    n = max(1, round((b - a) / spacing_m))
    return [quantise(a + (b - a) * k / n) for k in range(n + 1)]


def _connect_area(
    g: NavGraphBuilder, ids: list[list[int]], xs: list[float], ys: list[float], connect: dict[str, Corridor]
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


def _add_pillars(walls: Walls, xs: list[float], ys: list[float], pillar_size_m: float, pillar_sides: int) -> None:
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
                walls.rect((quantise(cx - h), quantise(cy - h), quantise(cx + h), quantise(cy + h)))
            else:
                a0 = math.pi / pillar_sides
                walls.polygon(
                    [
                        (cx + r * math.cos(a0 + 2 * math.pi * k / pillar_sides),
                         cy + r * math.sin(a0 + 2 * math.pi * k / pillar_sides))
                        for k in range(pillar_sides)
                    ]
                )


def assemble(
    walls: Walls,
    g: NavGraphBuilder,
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
