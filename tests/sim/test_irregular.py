"""Irregular generated floors: as far off square as a hand-drawn map, still a valid building."""

from __future__ import annotations

import hashlib
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.maps.freespace import label_components, rasterise
from sim.simulator.blueprints import (
    Blueprint,
    BuildingConfig,
    Irregularity,
    corridor_loop,
    generate_building,
    nav_edge_clearances,
)
from tests.sim.test_blueprints import _collinear_overlaps, _components, check_invariants

NONE = Irregularity.none()
ENV = BuildingConfig(width_m=30.0, height_m=24.0, name="procedural")  # the env's and RL splits' floors


def _digest(bp: Blueprint) -> str:
    return hashlib.sha256(np.ascontiguousarray(bp.vectormap.segments).tobytes()).hexdigest()[:16]


def _angle_diffs(seg: np.ndarray, mod_deg: float = 180.0) -> np.ndarray:
    """Angles (degrees) between walls that touch (ends within 5 cm) and run within 5
    degrees of each other (modulo ``mod_deg``: 90 also compares walls meeting at a corner)."""
    d = seg[:, 2:] - seg[:, :2]
    ang = np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 180.0
    pts = np.vstack([seg[:, :2], seg[:, 2:]])
    owner = np.r_[np.arange(len(seg)), np.arange(len(seg))]
    cells: dict[tuple[int, int], list[int]] = {}
    for k, (cx, cy) in enumerate(np.floor(pts / 0.05).astype(int).tolist()):
        cells.setdefault((cx, cy), []).append(k)
    pairs = set()
    for (cx, cy), ks in cells.items():
        near = [m for dx in (-1, 0, 1) for dy in (-1, 0, 1) for m in cells.get((cx + dx, cy + dy), [])]
        for k in ks:
            for m in near:
                i, j = owner[k], owner[m]
                if i < j and math.dist(pts[k], pts[m]) < 0.05:
                    pairs.add((i, j))
    p = np.array(sorted(pairs))
    diff = np.abs(ang[p[:, 0]] - ang[p[:, 1]]) % mod_deg
    diff = np.minimum(diff, mod_deg - diff)
    return diff[diff < 5.0]


def _angle_stats(diffs: list[np.ndarray]) -> tuple[int, float, float]:
    """How many pairs, the fraction exactly parallel (within 0.01 degrees), the median angle."""
    d = np.concatenate(diffs)
    return len(d), float((d < 0.01).mean()), float(np.median(d))


# --------------------------------------------------------------------------- off: exact geometry


# Digests of the walls before irregularity existed: switched off, the generator draws them again.
_EXACT = {
    ("default", 0): (BuildingConfig(irregularity=NONE), "f58c8d874a876f7b"),
    ("env", 3): (replace(ENV, irregularity=NONE), "04f55216b1f8e3c9"),
    ("wide", 1): (
        BuildingConfig(width_m=80.0, height_m=50.0, n_atria=2, block_width_m=28.0, block_length_m=13.0,
                       pillar_sides=8, pilaster_spacing_m=5.0, max_segment_m=1.0, irregularity=NONE),
        "bb84c09a1450946a",
    ),
    ("large", 0): (BuildingConfig.large(irregularity=NONE), "57f874c71c019e81"),
}


@pytest.mark.parametrize("key", sorted(_EXACT))
def test_off_draws_the_exact_floor(key):
    cfg, digest = _EXACT[key]
    bp = generate_building(cfg, key[1])
    assert _digest(bp) == digest
    zeros = Irregularity(
        max_wall_skew_deg=0, max_skew_offset_m=0, corner_jitter_m=0, recess_probability=0,
        jog_probability=0, double_line_probability=0, split_probability=0,
    )
    assert not zeros.active and zeros == NONE
    assert _digest(generate_building(replace(cfg, irregularity=zeros), key[1])) == digest


def test_the_shipped_corridor_loop_is_exact():
    seg = corridor_loop().vectormap.segments
    assert ((seg[:, 0] == seg[:, 2]) | (seg[:, 1] == seg[:, 3])).all()


def test_irregularity_is_on_by_default_and_keeps_the_layout():
    on, off = generate_building(ENV, 3), generate_building(replace(ENV, irregularity=NONE), 3)
    assert BuildingConfig().irregularity == Irregularity() and Irregularity().active
    assert on.navgraph == off.navgraph
    assert (on.rooms, on.open_areas, on.corridors) == (off.rooms, off.open_areas, off.corridors)
    seg = on.vectormap.segments
    assert not ((seg[:, 0] == seg[:, 2]) | (seg[:, 1] == seg[:, 3])).all()


# --------------------------------------------------------------------------- like a real floor


@pytest.mark.parametrize("cfg", [BuildingConfig(), ENV, BuildingConfig.large()], ids=["default", "env", "large"])
def test_statistics_like_a_hand_drawn_floor(cfg):
    """On GHC5 (a hand-drawn CoBot map) 17 % of touching, nearly parallel walls are exactly
    parallel, with a median angle of 0.73 degrees between them; counting corners (modulo
    90 degrees) 10 % are exact, median 1.07 degrees. The exact generator gives 100 % and 0."""
    seeds = range(4) if cfg.width_m < 100 else range(1)
    segs = [generate_building(cfg, seed).vectormap.segments for seed in seeds]
    n, exact, median = _angle_stats([_angle_diffs(s) for s in segs])
    assert n >= 20 and exact <= 0.3 and 0.3 <= median <= 2.0, (n, exact, median)
    n, exact, median = _angle_stats([_angle_diffs(s, 90.0) for s in segs])
    assert n >= 100 and exact <= 0.3 and 0.3 <= median <= 2.0, (n, exact, median)
    off = generate_building(replace(cfg, irregularity=NONE), 0).vectormap.segments
    assert _angle_stats([_angle_diffs(off, 90.0)])[1:] == (1.0, 0.0)


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    skew=st.floats(0.0, 3.0),
    offset=st.floats(0.0, 0.1),
    jitter=st.floats(0.0, 0.03),
)
def test_corners_move_within_the_bound(seed, skew, offset, jitter):
    """Skew and jitter alone keep every wall, each end within the bound along each axis."""
    irr = replace(NONE, max_wall_skew_deg=skew, max_skew_offset_m=offset, corner_jitter_m=jitter)
    cfg = replace(ENV, irregularity=irr)
    on = generate_building(cfg, seed).vectormap.segments
    off = generate_building(replace(cfg, irregularity=NONE), seed).vectormap.segments
    assert on.shape == off.shape
    moved = np.abs(on - off).max()
    assert moved <= irr.max_move_m + 0.0005 + 1e-9, moved
    if skew == 0.0 or offset == 0.0:
        assert moved <= jitter + 0.0005 + 1e-9


# --------------------------------------------------------------------------- still a valid building


def _rooms_closed(bp: Blueprint, cell: float) -> None:
    """With each doorway filled (a 1.7 x 0.4 m block across its nav edge), a flood from the
    room's centre stays in the room: a gap at a corner or T-junction would let it out."""
    g = bp.navgraph
    xy = g.node_xy()
    index = {int(n): k for k, n in enumerate(g.node_ids())}
    plugs = []  # door node on the wall line, and whether the door edge runs along y
    for e in g.edges:
        a, b = xy[index[e.s0_id]], xy[index[e.s1_id]]
        if e.has_door:
            plugs += [(a, a[0] == b[0]), (b, a[0] == b[0])]
    for room in bp.rooms:
        x0, y0, x1, y1 = room[0] - 1.0, room[1] - 1.0, room[2] + 1.0, room[3] + 1.0
        nx, ny = math.ceil((x1 - x0) / cell), math.ceil((y1 - y0) / cell)
        wall = rasterise(bp.vectormap.segments, x0, y0, cell, ny, nx)
        cx, cy = np.arange(nx) * cell + x0 + cell / 2, np.arange(ny) * cell + y0 + cell / 2
        for p, along_y in plugs:
            hx, hy = (0.85, 0.2) if along_y else (0.2, 0.85)
            wall[np.ix_(np.abs(cy - p[1]) <= hy, np.abs(cx - p[0]) <= hx)] = True
        lab, _ = label_components(~wall)
        mx, my = (room[0] + room[2]) / 2, (room[1] + room[3]) / 2
        rows, cols = np.nonzero(lab == lab[int((my - y0) / cell), int((mx - x0) / cell)])
        # inside the room box, give or take a jog (0.3 m) and the walls' moves
        assert rows.min() * cell >= 0.5 and cols.min() * cell >= 0.5, room
        assert (ny - 1 - rows.max()) * cell >= 0.5 and (nx - 1 - cols.max()) * cell >= 0.5, room


def test_irregular_floors_are_valid_buildings():
    for cfg, seed, fine in ((BuildingConfig(), 0, False), (ENV, 1, True)):
        bp = generate_building(cfg, seed)
        check_invariants(bp, reference=fine)
        _rooms_closed(bp, 0.005 if fine else 0.01)


_RICH = Irregularity(recess_probability=1.0, jog_probability=1.0, double_line_probability=0.5, split_probability=0.5)


@settings(max_examples=12, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    heavy=st.booleans(),
    max_segment=st.sampled_from([None, 0.5]),
    door=st.sampled_from([(0.9, 1.0), (0.7, 0.75)]),
)
def test_irregular_floors_stay_valid(seed, heavy, max_segment, door):
    """Any seed, the default irregularity or every edit at its most frequent, narrow doors
    (0.35 m of clearance left): the graph keeps its clearance, rooms stay closed, no wall
    overlaps another."""
    irr = _RICH if heavy else Irregularity()
    cfg = replace(ENV, irregularity=irr, max_segment_m=max_segment, door_width_range_m=door)
    bp = generate_building(cfg, seed)
    assert nav_edge_clearances(bp).min() >= cfg.min_clearance_m - 1e-9  # 0.7 m doors: exactly 0.35
    assert _components(bp.navgraph) == 1
    assert _collinear_overlaps(bp.vectormap.segments) == []
    assert (bp.vectormap.lengths > 1e-3).all()
    if max_segment is not None:
        assert bp.vectormap.lengths.max() <= max_segment + 2 * math.sqrt(2) * irr.max_move_m + 1e-3
    _rooms_closed(bp, 0.01)


@pytest.mark.xfail(strict=True, reason="at twice the default skew, skew offset and corner jitter a wall end "
                   "leaves a gap in a room on the outer wall (seed 1957); the generator does not keep it closed yet")
def test_twice_the_default_skew_and_jitter_keeps_rooms_closed():
    irr = Irregularity(max_wall_skew_deg=3.0, max_skew_offset_m=0.1, corner_jitter_m=0.03)
    bp = generate_building(replace(ENV, irregularity=irr, door_width_range_m=(0.9, 1.0)), 1957)
    _rooms_closed(bp, 0.01)


def test_recesses_jogs_doubles_and_splits_happen():
    off = generate_building(replace(ENV, irregularity=NONE), 2)
    on = generate_building(replace(ENV, irregularity=_RICH), 2)
    assert on.vectormap.n_segments > 1.5 * off.vectormap.n_segments
    lengths = on.vectormap.lengths
    assert ((lengths > 0.1) & (lengths < 0.3)).sum() >= 10  # recess and jog sides


# --------------------------------------------------------------------------- seeds and checks


def test_deterministic_per_seed():
    a = generate_building(ENV, 7)
    b = generate_building(ENV, np.random.default_rng(7))
    assert np.array_equal(a.vectormap.segments, b.vectormap.segments)
    c = generate_building(ENV, 8)
    assert a.vectormap.n_segments != c.vectormap.n_segments or not np.array_equal(
        a.vectormap.segments, c.vectormap.segments
    )


@pytest.mark.parametrize(
    "kw, needle",
    [
        ({"max_wall_skew_deg": -1.0}, "max_wall_skew_deg"),
        ({"max_wall_skew_deg": 20.0}, "max_wall_skew_deg"),
        ({"corner_jitter_m": 0.5}, "corner_jitter_m"),
        ({"recess_probability": 1.5}, "recess_probability"),
        ({"recess_depth_m": (0.3, 0.2)}, "recess_depth_m"),
        ({"double_line_gap_m": (0.01, 0.05)}, "double_line_gap_m"),
        ({"split_probability": float("nan")}, "split_probability"),
    ],
)
def test_irregularity_validation(kw, needle):
    with pytest.raises(InputError, match=needle):
        Irregularity(**kw)


def test_building_config_wants_an_irregularity():
    with pytest.raises(InputError, match="irregularity"):
        BuildingConfig(irregularity="none")  # type: ignore[arg-type]
