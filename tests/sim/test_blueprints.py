"""Blueprint invariants for the shipped floors and the procedural generator."""

from __future__ import annotations

import json
from collections import deque
from dataclasses import replace

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.maps.navgraph import NavGraph
from autonomy.maps.vectormap import MapFormatError
from sim.simulator.blueprints import (
    ASSETS_DIR,
    SHIPPED,
    Blueprint,
    BuildingConfig,
    corridor_loop,
    generate_building,
    load_blueprint,
    main,
    nav_edge_clearances,
    save_blueprint,
    segment_distances,
    small_floor,
)

ROBOT_CLEARANCE_M = 0.35


# --------------------------------------------------------------------------- reference geometry


def _ref_seg_dist_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact distance between every segment of a (M x 4) and of b (K x 4): M x K.

    Two 2D segments that do not cross are closest at an endpoint of one of them."""
    A0, A1 = a[:, None, 0:2], a[:, None, 2:4]
    B0, B1 = b[None, :, 0:2], b[None, :, 2:4]

    def pt_seg(p, s0, s1):
        d = s1 - s0
        L2 = (d * d).sum(-1)
        t = np.clip(((p - s0) * d).sum(-1) / np.where(L2 == 0, 1, L2), 0, 1)
        c = s0 + t[..., None] * d
        return np.linalg.norm(p - c, axis=-1)

    dist = np.minimum.reduce(
        [pt_seg(A0, B0, B1), pt_seg(A1, B0, B1), pt_seg(B0, A0, A1), pt_seg(B1, A0, A1)]
    )

    def orient(p, q, r):
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    cross = (orient(A0, A1, B0) * orient(A0, A1, B1) < 0) & (orient(B0, B1, A0) * orient(B0, B1, A1) < 0)
    return np.where(cross, 0.0, dist)


def _ref_edge_clearance(bp: Blueprint) -> np.ndarray:
    e = bp.navgraph.edge_segments()
    w = bp.vectormap.segments
    out = []
    for s in range(0, e.shape[0], 64):
        out.append(_ref_seg_dist_matrix(e[s : s + 64], w).min(axis=1))
    return np.concatenate(out)


def _components(g: NavGraph) -> int:
    seen: set[int] = set()
    n = 0
    for node in g.nodes:
        if node.id in seen:
            continue
        n += 1
        q = deque([node.id])
        seen.add(node.id)
        while q:
            for m in g.neighbors(q.popleft()):
                if m not in seen:
                    seen.add(m)
                    q.append(m)
    return n


def _collinear_overlaps(seg: np.ndarray, tol: float = 1e-6) -> list[tuple[int, int]]:
    """Pairs of segments on the same line whose extents overlap by more than ``tol``."""
    d = seg[:, 2:4] - seg[:, 0:2]
    ang = np.mod(np.arctan2(d[:, 1], d[:, 0]), np.pi)
    ang = np.where(np.isclose(ang, np.pi, atol=1e-9), 0.0, ang)
    u = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    off = -u[:, 1] * seg[:, 0] + u[:, 0] * seg[:, 1]
    t0 = (u * seg[:, 0:2]).sum(1)
    t1 = (u * seg[:, 2:4]).sum(1)
    lo, hi = np.minimum(t0, t1), np.maximum(t0, t1)
    groups: dict[tuple[float, float], list[int]] = {}
    for i, key in enumerate(zip(np.round(ang, 7).tolist(), np.round(off, 5).tolist(), strict=True)):
        groups.setdefault(key, []).append(i)
    bad = []
    for idx in groups.values():
        idx = sorted(idx, key=lambda i: lo[i])
        reach, who = -np.inf, -1
        for i in idx:
            if lo[i] < reach - tol:
                bad.append((who, i))
            if hi[i] > reach:
                reach, who = hi[i], i
    return bad


def _box_contains(box, x, y, margin=0.0):
    return box[0] + margin <= x <= box[2] - margin and box[1] + margin <= y <= box[3] - margin


def check_invariants(bp: Blueprint, reference: bool = True) -> None:
    g = bp.navgraph
    vm = bp.vectormap
    assert vm.n_segments > 0 and g.n_nodes > 0 and g.n_edges > 0
    # 1. every nav edge keeps the robot (radius 0.3 m) clear of every wall
    clear = _ref_edge_clearance(bp) if reference else nav_edge_clearances(bp)
    worst = int(np.argmin(clear))
    assert clear[worst] >= ROBOT_CLEARANCE_M, (bp.name, g.edges[worst], clear[worst])
    # 2. connected
    assert _components(g) == 1
    # 3. every room has a node inside it (reachable, since the graph is connected), entered
    #    through a door edge
    xy = g.node_xy()
    door_nodes = {e.s0_id for e in g.edges if e.has_door} | {e.s1_id for e in g.edges if e.has_door}
    ids = g.node_ids()
    for room in bp.rooms:
        inside = (xy[:, 0] > room[0]) & (xy[:, 0] < room[2]) & (xy[:, 1] > room[1]) & (xy[:, 1] < room[3])
        assert inside.any(), room
        cx, cy = (room[0] + room[2]) / 2, (room[1] + room[3]) / 2
        assert np.min(np.hypot(xy[:, 0] - cx, xy[:, 1] - cy)) <= 0.001, f"no node at the centre of {room}"
        assert any(i in door_nodes for i in ids[inside].tolist()), f"room {room} has no door edge"
    for area in bp.open_areas:
        assert ((xy[:, 0] > area[0]) & (xy[:, 0] < area[2]) & (xy[:, 1] > area[1]) & (xy[:, 1] < area[3])).sum() >= 2
    # 4. no two walls overlap collinearly, walls are all finite non-degenerate
    assert _collinear_overlaps(vm.segments) == []
    assert (vm.lengths > 1e-6).all()
    # 5. no nav node sits outside the building
    x0, y0, x1, y1 = vm.extent()
    assert ((xy[:, 0] > x0) & (xy[:, 0] < x1) & (xy[:, 1] > y0) & (xy[:, 1] < y1)).all()


# --------------------------------------------------------------------------- helpers' own tests


def test_segment_distance_cases():
    a = np.array([[0, 0, 2, 0], [0, 0, 2, 0], [0, 0, 2, 0], [0, 0, 2, 0], [0, 0, 2, 0], [0, 0, 1, 1]], float)
    b = np.array([[1, -1, 1, 1], [3, 0, 4, 0], [1, 0.5, 1, 3], [2, 0, 3, 0], [0.5, 1, 1.5, 1], [1, 0, 2, -1]], float)
    np.testing.assert_allclose(segment_distances(a, b), [0.0, 1.0, 0.5, 0.0, 1.0, np.sqrt(0.5)])
    np.testing.assert_allclose(np.diag(_ref_seg_dist_matrix(a, b)), segment_distances(a, b))


def test_nav_edge_clearances_matches_reference():
    bp = generate_building(BuildingConfig(max_segment_m=2.0), 11)
    ref = np.minimum(_ref_edge_clearance(bp), 5.0)
    np.testing.assert_allclose(nav_edge_clearances(bp), ref, atol=1e-12)


# --------------------------------------------------------------------------- shipped floors


@pytest.fixture(scope="module")
def shipped() -> dict[str, Blueprint]:
    return {name: fn() for name, fn in SHIPPED.items()}


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_invariants(shipped, name):
    check_invariants(shipped[name])


def test_corridor_loop_shape(shipped):
    bp = shipped["corridor_loop"]
    x0, y0, x1, y1 = bp.extent()
    assert 55 <= x1 - x0 <= 65 and 35 <= y1 - y0 <= 45
    assert len(bp.open_areas) >= 1
    big = [a for a in bp.open_areas if (a[2] - a[0]) * (a[3] - a[1]) >= 12 * 10]
    assert big, bp.open_areas
    assert len(bp.rooms) >= 30 and len(bp.corridors) >= 4
    cx0, cy0, cx1, cy1 = (
        min(c[0] for c in bp.corridors), min(c[1] for c in bp.corridors),
        max(c[2] for c in bp.corridors), max(c[3] for c in bp.corridors),
    )
    outside = [r for r in bp.rooms if r[2] <= cx0 or r[0] >= cx1 or r[3] <= cy0 or r[1] >= cy1]
    inside = [r for r in bp.rooms if r[0] >= cx0 and r[2] <= cx1 and r[1] >= cy0 and r[3] <= cy1]
    assert outside and inside, "offices both outside and inside the corridor loop"
    assert 1000 <= bp.vectormap.n_segments <= 9000


def test_small_floor_shape(shipped):
    bp = shipped["small_floor"]
    x0, y0, x1, y1 = bp.extent()
    assert (x1 - x0, y1 - y0) == (16.0, 10.0)
    assert 3 <= len(bp.rooms) <= 4 and len(bp.open_areas) == 1 and len(bp.corridors) == 1


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_shipped_assets_match_generators(shipped, name):
    """The files in sim/assets are exactly what the functions produce (run
    ``python -m sim.simulator.blueprints`` after changing a generator)."""
    bp = shipped[name]
    disk = load_blueprint(ASSETS_DIR / name)
    assert disk.name == bp.name == name
    assert np.array_equal(disk.vectormap.segments, bp.vectormap.segments)
    assert disk.navgraph == bp.navgraph
    assert (disk.rooms, disk.open_areas, disk.corridors) == (bp.rooms, bp.open_areas, bp.corridors)
    assert load_blueprint(name).navgraph == bp.navgraph  # bare shipped names resolve to sim/assets


def test_main_writes_assets(tmp_path, capsys):
    assert main(["--out", str(tmp_path)]) == 0
    for name in SHIPPED:
        for suf in (".vectormap.txt", ".navigation.json", ".zones.json"):
            assert (tmp_path / (name + suf)).stat().st_size > 0
            assert (tmp_path / (name + suf)).read_bytes() == (ASSETS_DIR / (name + suf)).read_bytes()
    assert "corridor_loop" in capsys.readouterr().out


# --------------------------------------------------------------------------- generator


_CONFIGS = {
    "default": BuildingConfig(),
    "no_atrium": BuildingConfig(width_m=40.0, height_m=30.0, n_atria=0),
    "wide_blocks": BuildingConfig(width_m=80.0, height_m=50.0, n_atria=2, block_width_m=28.0, block_length_m=13.0,
                                  pillar_sides=8, pilaster_spacing_m=5.0, max_segment_m=1.0),
    "narrow": BuildingConfig(width_m=34.0, height_m=30.0, corridor_width_range_m=(2.0, 2.0),
                             room_width_range_m=(2.6, 3.0), door_width_range_m=(0.9, 0.9)),
}


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("cfg_name", sorted(_CONFIGS))
def test_generator_invariants(cfg_name, seed):
    bp = generate_building(_CONFIGS[cfg_name], seed)
    check_invariants(bp, reference=(seed == 0))
    if _CONFIGS[cfg_name].n_atria:
        assert len(bp.open_areas) == _CONFIGS[cfg_name].n_atria


def test_generator_deterministic_and_seed_sensitive():
    cfg = BuildingConfig(max_segment_m=1.0)
    a = generate_building(cfg, 42)
    b = generate_building(cfg, np.random.default_rng(42))
    assert np.array_equal(a.vectormap.segments, b.vectormap.segments)
    assert a.navgraph == b.navgraph
    assert (a.rooms, a.open_areas, a.corridors) == (b.rooms, b.open_areas, b.corridors)
    c = generate_building(cfg, 43)
    assert c.vectormap.n_segments != a.vectormap.n_segments or not np.array_equal(
        c.vectormap.segments, a.vectormap.segments
    )
    assert c.rooms != a.rooms


def test_large_floor_size_and_invariants():
    """``make bench``'s blueprint_large times this generation."""
    bp = generate_building(BuildingConfig.large(), 0)
    assert bp.vectormap.n_segments >= 9000
    x0, y0, x1, y1 = bp.extent()
    # irregular walls: an exterior jog reaches up to 0.3 m out, a corner moves a few cm
    assert abs(x1 - x0 - 100.0) <= 0.5 and abs(y1 - y0 - 100.0) <= 0.5
    assert len(bp.open_areas) == 3
    check_invariants(bp, reference=False)


def test_large_overrides():
    cfg = BuildingConfig.large(n_atria=1, name="x")
    assert cfg.width_m == 100.0 and cfg.n_atria == 1 and cfg.name == "x"


@pytest.mark.parametrize(
    "kw, needle",
    [
        ({"corridor_width_range_m": (2.5, 2.0)}, "corridor_width_range_m"),
        ({"corridor_width_range_m": (1.0, 1.2)}, "corridor_width_range_m"),
        ({"door_width_range_m": (0.5, 0.6)}, "door_width_range_m"),
        ({"room_width_range_m": (1.5, 3.0)}, "room_width_range_m"),
        ({"width_m": 15.0}, "footprint"),
        ({"width_m": -1.0}, "width_m"),
        ({"max_segment_m": 0.0}, "max_segment_m"),
        ({"large_room_prob": 2.0}, "large_room_prob"),
    ],
)
def test_config_validation(kw, needle):
    with pytest.raises(InputError, match=needle):
        BuildingConfig(**kw)


def test_too_many_atria():
    with pytest.raises(InputError, match="n_atria"):
        generate_building(replace(BuildingConfig(), n_atria=50), 0)


# --------------------------------------------------------------------------- files


def test_blueprint_round_trip(tmp_path):
    bp = generate_building(BuildingConfig(n_atria=0, name="rt"), 5)
    paths = save_blueprint(bp, tmp_path / "sub" / "rt")
    assert [p.name for p in paths] == ["rt.vectormap.txt", "rt.navigation.json", "rt.zones.json"]
    back = load_blueprint(tmp_path / "sub" / "rt.navigation.json")
    assert np.array_equal(back.vectormap.segments, bp.vectormap.segments)
    assert back.navgraph == bp.navgraph and back.rooms == bp.rooms and back.name == "rt"
    zones = json.loads(paths[2].read_text())
    assert set(zones) == {"name", "rooms", "open_areas", "corridors"}


def test_load_blueprint_errors(tmp_path):
    with pytest.raises(MapFormatError, match="file not found"):
        load_blueprint(tmp_path / "missing")
    save_blueprint(small_floor(), tmp_path / "s")
    z = tmp_path / "s.zones.json"
    z.write_text('{"name": "s", "rooms": [[0, 0, 1]]}')
    with pytest.raises(MapFormatError, match=r"s\.zones\.json: rooms\[0\]: expected a box"):
        load_blueprint(tmp_path / "s")
    z.write_text('{"rooms": [')
    with pytest.raises(MapFormatError, match=r"s\.zones\.json:1:\d+: invalid JSON"):
        load_blueprint(tmp_path / "s")
    z.unlink()
    with pytest.raises(MapFormatError, match=r"s\.zones\.json: file not found"):
        load_blueprint(tmp_path / "s")


def test_corridor_loop_is_cached_free_and_repeatable():
    a, b = corridor_loop(), corridor_loop()
    assert a is not b and np.array_equal(a.vectormap.segments, b.vectormap.segments)
