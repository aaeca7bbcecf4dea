"""The procedural office floor: a seeded corridor-loop / grid building.

:func:`generate_building` draws a seeded corridor-loop / grid office floor: a ring of
offices along the exterior walls, a corridor loop, and blocks of double-loaded offices
between internal corridors, some of them (partly) replaced by open atria with pillars.
Doorways are gaps in the walls. Nav-graph edges keep at least
``config.min_clearance_m`` from every wall. ``config.irregularity``
(:class:`~sim.simulator.irregular.Irregularity`, on by default) then makes the walls as
irregular as a hand-drawn map's: slightly skewed, corners jittered, door recesses, jogs,
broken and doubled lines.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from sim.simulator.floorplan import (
    DOOR_INNER_M,
    DOOR_JAMB_MARGIN_M,
    Blueprint,
    Box,
    Corridor,
    NavGraphBuilder,
    Walls,
    add_open_area,
    add_room,
    assemble,
    quantise,
)
from sim.simulator.irregular import Irregularity, irregular_walls


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
        need = self.door_width_range_m[1] + 2 * DOOR_JAMB_MARGIN_M + 0.2
        if self.room_width_range_m[0] < need:
            raise bad("room_width_range_m", f"rooms at least {need:.2f} m wide (door plus jambs)")
        if self.room_depth_range_m[0] < 2 * DOOR_INNER_M + 0.5 or self.outer_room_depth_range_m[0] < 2 * DOOR_INNER_M + 0.5:
            raise bad("room_depth_range_m", f"rooms at least {2 * DOOR_INNER_M + 0.5:.2f} m deep")
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
    return [quantise(c) for c in cuts]


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
        a = quantise(t)
        t += sizes[k]
        b = quantise(t) if k < n - 1 else quantise(hi)
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


def _block_facing(box: Box, side_c: dict[str, Corridor]) -> tuple[bool, Corridor, Corridor]:
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
        cut = quantise(y0 + a_len) if at_low else quantise(y1 - a_len)
        lo, hi = (x0, y0, x1, cut), (x0, cut, x1, y1)
        return (lo, hi, "N") if at_low else (hi, lo, "S")
    cut = quantise(x0 + a_len) if at_low else quantise(x1 - a_len)
    lo, hi = (x0, y0, cut, y1), (cut, y0, x1, y1)
    return (lo, hi, "E") if at_low else (hi, lo, "W")


@dataclass
class _Grid:
    """The corridors of a drawn floor: the loop and the internal corridors between blocks."""

    depth: dict[str, float]
    """Depth of the outer offices on each side ('S', 'N', 'W', 'E')."""
    cols: list[tuple[float, float]]
    """x span of each column of blocks inside the loop."""
    rows: list[tuple[float, float]]
    """y span of each row of blocks inside the loop."""
    vcorrs: list[Corridor]
    """Vertical corridors west to east (the loop's west side first, its east side last)."""
    hcorrs: list[Corridor]
    """Horizontal corridors south to north (the loop's south side first, its north side last)."""


class _Floor:
    """One floor being drawn: its config, random stream, walls, nav graph and zones.

    The methods draw from ``rng`` in a fixed order, so a config and a seed give one floor.
    """

    def __init__(self, cfg: BuildingConfig, rng: np.random.Generator) -> None:
        self.cfg, self.rng = cfg, rng
        self.walls, self.g = Walls(), NavGraphBuilder()
        self.rooms: list[Box] = []
        self.areas: list[Box] = []
        self.W, self.H = quantise(cfg.width_m), quantise(cfg.height_m)

    def uni(self, r: tuple[float, float]) -> float:
        """One uniform draw from the range ``r``, quantised."""
        return quantise(self.rng.uniform(r[0], r[1]))

    def room(self, box: Box, door_side: str, corr: Corridor) -> None:
        """An office with a door of drawn width on ``door_side``, facing ``corr``."""
        door_w = self.uni(self.cfg.door_width_range_m)
        add_room(self.walls, self.g, self.rooms, box, door_side, corr, door_w, self.rng)

    def draw_grid(self) -> _Grid:
        """The corridor loop inside the outer offices, and the corridors between the blocks."""
        cfg, W, H = self.cfg, self.W, self.H
        d_b, d_t, d_l, d_r = (self.uni(cfg.outer_room_depth_range_m) for _ in range(4))
        cw_b, cw_t, cw_l, cw_r = (self.uni(cfg.corridor_width_range_m) for _ in range(4))
        ix0, ix1 = quantise(d_l + cw_l), quantise(W - d_r - cw_r)
        iy0, iy1 = quantise(d_b + cw_b), quantise(H - d_t - cw_t)
        left = Corridor(False, (d_l, d_b, ix0, quantise(H - d_t)), 0.0, 0.0)
        right = Corridor(False, (ix1, d_b, quantise(W - d_r), quantise(H - d_t)), 0.0, 0.0)
        bottom = Corridor(True, (d_l, d_b, quantise(W - d_r), iy0), left.c, right.c)
        top = Corridor(True, (d_l, iy1, quantise(W - d_r), quantise(H - d_t)), left.c, right.c)
        left.lo, left.hi = bottom.c, top.c
        right.lo, right.hi = bottom.c, top.c
        n_cols = _n_blocks(ix1 - ix0, cfg.block_width_m, cfg)
        n_rows = _n_blocks(iy1 - iy0, cfg.block_length_m, cfg)
        vgaps = [self.uni(cfg.corridor_width_range_m) for _ in range(n_cols - 1)]
        hgaps = [self.uni(cfg.corridor_width_range_m) for _ in range(n_rows - 1)]
        cols = _split_range(ix0, ix1, n_cols, vgaps, self.rng)
        rows = _split_range(iy0, iy1, n_rows, hgaps, self.rng)
        inner_v = [
            Corridor(False, (cols[k][1], iy0, cols[k + 1][0], iy1), bottom.c, top.c) for k in range(n_cols - 1)
        ]
        inner_h = [
            Corridor(True, (ix0, rows[k][1], ix1, rows[k + 1][0]), left.c, right.c) for k in range(n_rows - 1)
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
            lo, hi = (d["W"], quantise(W - d["E"])) if side in "SN" else (d["S"], quantise(H - d["N"]))
            cuts = [quantise(lo + c) for c in _partition(hi - lo, wmin, wmax, cfg.large_room_prob, self.rng)]
            bounds = [0.0, *cuts, W] if side in "SN" else [lo, *cuts, hi]
            joints[side] = bounds
            for a, b in zip(bounds[:-1], bounds[1:], strict=True):
                self.room(*self._outer_room(grid, side, a, b))
        self.walls.rect((0.0, 0.0, W, H))
        return joints

    def _outer_room(self, grid: _Grid, side: str, a: float, b: float) -> tuple[Box, str, Corridor]:
        """The box of an outer office spanning ``a..b`` on ``side``, its door side and corridor."""
        W, H, d = self.W, self.H, grid.depth
        if side == "S":
            return (a, 0.0, b, d["S"]), "N", grid.hcorrs[0]
        if side == "N":
            return (a, quantise(H - d["N"]), b, H), "S", grid.hcorrs[-1]
        if side == "W":
            return (0.0, a, d["W"], b), "E", grid.vcorrs[0]
        return (quantise(W - d["E"]), a, W, b), "W", grid.vcorrs[-1]

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

    def fill_rooms(self, box: Box, vertical: bool, lo_c: Corridor, hi_c: Corridor) -> None:
        """Offices in ``box``: rows along y facing W/E corridors (vertical) or along x facing S/N."""
        x0, y0, x1, y1 = box
        v0, v1, u0, u1 = (x0, x1, y0, y1) if vertical else (y0, y1, x0, x1)
        lo_side, hi_side = ("W", "E") if vertical else ("S", "N")
        if v1 - v0 < 2 * self.cfg.room_depth_range_m[0]:
            row_specs = [(v0, v1, lo_c, lo_side)]
        else:
            da, db = self._row_depths(vertical, u0, u1, v0, v1)
            row_specs = [(v0, quantise(v0 + da), lo_c, lo_side), (quantise(v1 - db), v1, hi_c, hi_side)]
        wmin, wmax = self.cfg.room_width_range_m
        for va, vb, corr, dside in row_specs:
            cuts = _partition(u1 - u0, wmin, wmax, self.cfg.large_room_prob, self.rng)
            bounds = [u0] + [quantise(u0 + c) for c in cuts] + [u1]
            for a, b in zip(bounds[:-1], bounds[1:], strict=True):
                self.room(_block_box(vertical, a, b, va, vb), dside, corr)

    def _row_depths(self, vertical: bool, u0: float, u1: float, v0: float, v1: float) -> tuple[float, float]:
        """Depths of a block's two office rows; a block deeper than two rows plus
        ``min_core_m`` gets a closed service core between them."""
        cfg = self.cfg
        span = v1 - v0
        if span <= 2 * cfg.room_depth_range_m[1] + cfg.min_core_m:
            da = quantise(span * self.rng.uniform(0.45, 0.55))
            return da, quantise(span - da)
        da, db = self.uni(cfg.room_depth_range_m), self.uni(cfg.room_depth_range_m)
        self._add_core(_block_box(vertical, u0, u1, quantise(v0 + da), quantise(v1 - db)), vertical, u0, u1)
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

    def add_atrium_block(self, box: Box, side_c: dict[str, Corridor]) -> None:
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
        add_open_area(
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
    return assemble(
        floor.walls, floor.g, floor.rooms, floor.areas, [c.box for c in corridors], config.max_segment_m,
        config.name, segments,
    )


def _add_pilasters(
    walls: Walls, W: float, H: float, joints: dict[str, list[float]], spacing: float
) -> None:
    """Pilasters (0.4 m wide, 0.3 m deep jogs) along the inside of the exterior walls."""
    half, depth = 0.2, 0.3
    for side in "SNWE":
        length = W if side in "SN" else H
        js = list(joints[side]) + [0.0, length]
        t = spacing / 2
        while t < length:
            p = quantise(t)
            t += spacing
            if min(abs(p - j) for j in js) < half + 0.6:
                continue
            a, b = quantise(p - half), quantise(p + half)
            if side == "S":
                walls.gap_h(0.0, a, b)
                walls.hline(depth, a, b)
                walls.vline(a, 0.0, depth)
                walls.vline(b, 0.0, depth)
            elif side == "N":
                walls.gap_h(H, a, b)
                walls.hline(quantise(H - depth), a, b)
                walls.vline(a, quantise(H - depth), H)
                walls.vline(b, quantise(H - depth), H)
            elif side == "W":
                walls.gap_v(0.0, a, b)
                walls.vline(depth, a, b)
                walls.hline(a, 0.0, depth)
                walls.hline(b, 0.0, depth)
            else:
                walls.gap_v(W, a, b)
                walls.vline(quantise(W - depth), a, b)
                walls.hline(a, quantise(W - depth), W)
                walls.hline(b, quantise(W - depth), W)
