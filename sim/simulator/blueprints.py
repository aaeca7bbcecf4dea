"""Office-building blueprints: a vector map of thin walls, a matching nav graph, and zones.

A :class:`Blueprint` is what the simulator builds a world from: walls as 2D segments
(:class:`autonomy.maps.vectormap.VectorMap`), a UT AMRL-style navigation graph, and the boxes
of the offices, open areas (atria) and corridors, so scenarios can place furniture and
people.

:func:`generate_building` draws a seeded corridor-loop / grid office floor
(:mod:`sim.simulator.floor_generator`; :class:`Blueprint` and the drawing parts live in
:mod:`sim.simulator.floorplan`). This module holds the shipped floors and the blueprint
files (:func:`save_blueprint`, :func:`load_blueprint`), and re-exports the public names of
the other two so ``sim.simulator.blueprints`` stays the one place to import them from.

Two fixed buildings ship in ``sim/assets`` (``python -m sim.simulator.blueprints`` regenerates
them): :func:`corridor_loop` (about 60 x 40 m) and :func:`small_floor` (16 x 10 m).
"""

from __future__ import annotations

import argparse
import json
import math
import os
from collections.abc import Sequence
from pathlib import Path

from autonomy.common.geometry import segment_distances
from autonomy.maps.navgraph import load_navgraph, save_navgraph
from autonomy.maps.vectormap import MapFormatError, VectorMap, load_vectormap, save_vectormap
from sim.simulator.floor_generator import BuildingConfig, generate_building
from sim.simulator.floorplan import (
    Blueprint,
    Box,
    Corridor,
    NavGraphBuilder,
    Walls,
    add_room,
    assemble,
    nav_edge_clearances,
    node_grid,
)
from sim.simulator.irregular import Irregularity

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

ASSETS_DIR = Path(__file__).resolve().parent.parent / "assets"
"""Where the shipped blueprints live."""


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
    walls, g = Walls(), NavGraphBuilder()
    rooms: list[Box] = []
    areas: list[Box] = []
    corr = Corridor(True, (0.0, 4.0, 10.0, 6.2), 1.1, 10.0)
    walls.rect((0.0, 0.0, 16.0, 10.0))
    add_room(walls, g, rooms, (0.0, 6.2, 5.0, 10.0), "S", corr, 0.95, door_t=3.9)
    add_room(walls, g, rooms, (5.0, 6.2, 10.0, 10.0), "S", corr, 0.95, door_t=6.2)
    add_room(walls, g, rooms, (0.0, 0.0, 5.5, 4.0), "N", corr, 0.95, door_t=4.2)
    add_room(walls, g, rooms, (5.5, 0.0, 10.0, 4.0), "N", corr, 0.95, door_t=6.8)
    box = (10.0, 0.0, 16.0, 10.0)
    areas.append(box)
    xs, ys = (11.5, 14.5), (1.5, 5.1, 8.5)
    ids = node_grid(g, xs, ys)
    corr.chain(g, 3.0)
    g.edge(g.node(10.0, 5.1), ids[1][0], max_clearance=1.0)
    walls.rect((12.8, 3.1, 13.2, 3.5))  # one pillar between the open area's nodes
    return assemble(walls, g, rooms, areas, [corr.box], 2.0, "small_floor")


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
