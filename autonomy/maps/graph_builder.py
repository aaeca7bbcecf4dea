"""Navigation graphs made from the walls alone (UT AMRL ``navigation.json`` format).

1. :func:`~autonomy.maps.freespace.build_free_space` finds the inside regions where the robot fits.
2. The cells at least ``robot radius + margin`` from every wall are thinned to a
   one-cell skeleton (Zhang and Suen, "A fast parallel algorithm for thinning digital
   patterns", CACM 1984), which runs along corridor centre lines, through doorways into
   rooms and between pillars, and keeps the free space's topology (one piece per region).
3. The skeleton is traced into branches between junctions and ends; dead-end spurs that
   end within the junction's clearance plus ``spur_m`` (towards room corners, wall
   irregularities) are pruned.
4. Each branch becomes straight edges of at most ``max_edge_m`` that stay within
   ``tolerance_m`` of it and keep ``robot radius + margin`` from every wall, checked
   exactly against the segments (:class:`~autonomy.common.geometry.WallIndex`).
5. Free space farther than ``cover_radius_m`` from every edge (wide halls, open sites)
   gets a square lattice of nodes ``cover_spacing_m`` apart, turned to the walls' main
   direction, joined to its lattice neighbours and to the graph by clear straight edges;
   what the lattice misses (room corners) gets single nodes, farthest first.
6. The graph is thinned: nodes joined by an edge shorter than ``merge_m`` become one, and
   a node between two others is dropped when the straight edge between them stays clear,
   within ``tolerance_m`` of it and no longer than ``max_edge_m`` (a door edge is kept
   apart from the edges around it, so its speed limit stays on the doorway).

Every step keeps the clearance of every edge exact; the thinning trades at most
``tolerance_m`` of coverage at the graph's fringe for a few nodes per room.

Edges narrower than ``door_clearance_m`` are marked ``has_door`` with the door speed;
``max_clearance`` is each edge's exact clearance.

The stages live in sibling modules: the settings in :mod:`~autonomy.maps.graph_config`,
steps 2 and 3 in :mod:`~autonomy.maps.graph_skeleton`, steps 4 and 6 in
:mod:`~autonomy.maps.graph_edges`, step 5 in :mod:`~autonomy.maps.graph_cover`; this
module runs them and caches the result.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from autonomy.common.cache import cache_paths
from autonomy.common.geometry import WallIndex
from autonomy.maps.freespace import FreeSpace, build_free_space
from autonomy.maps.graph_config import GraphBuildConfig
from autonomy.maps.graph_cover import (
    _cover,
    _lattice,
    distance_to_cells,
    distance_to_segments,
    dominant_angle,
)
from autonomy.maps.graph_edges import _Builder, _simplify, graph_components
from autonomy.maps.graph_skeleton import _branches, thin
from autonomy.maps.navgraph import (
    DEFAULT_MAX_SPEED,
    NavEdge,
    NavGraph,
    NavNode,
    format_navgraph_json,
    parse_navgraph_json,
)
from autonomy.maps.vectormap import VectorMap

__all__ = [
    "GraphBuildConfig",
    "GraphBuild",
    "CachedGraph",
    "build_navgraph",
    "cached_navgraph",
    "load_or_build_navgraph",
    "graph_components",
    "graph_key",
    "with_key",
    "thin",
    "dominant_angle",
    "distance_to_segments",
    "distance_to_cells",
]


@dataclass(frozen=True, eq=False)
class GraphBuild:
    """A generated graph with the free space it was made from."""

    graph: NavGraph
    """The navigation graph."""
    free_space: FreeSpace
    """Where the robot fits, by region."""
    node_region: np.ndarray
    """(N,) region of each node (node order)."""
    component: np.ndarray
    """(N,) connected component of each node, 0 the largest."""
    narrow_regions: tuple[int, ...]
    """Regions the robot fits in but no edge with the margin does (no nodes there)."""
    split_regions: tuple[int, ...]
    """Regions whose graph falls into several components (a passage the robot fits
    through only without the margin)."""

    @property
    def n_components(self) -> int:
        """Connected components of the graph."""
        return int(self.component.max()) + 1 if self.component.size else 0

    def main_node_ids(self) -> np.ndarray:
        """Ids of the nodes in the largest connected component."""
        return self.graph.node_ids()[self.component == 0]

    def summary(self) -> str:
        """One line: nodes, edges, components, regions."""
        fs = self.free_space
        return (
            f"{self.graph.n_nodes} nodes, {self.graph.n_edges} edges, {self.n_components} component(s); "
            f"{fs.n_regions} inside region(s), {fs.region_area_m2.sum():.0f} m2 free for the robot "
            f"(largest {fs.region_area_m2[0]:.0f} m2)"
        )


# --------------------------------------------------------------------------- construction


def build_navgraph(vm: VectorMap, cfg: GraphBuildConfig = GraphBuildConfig()) -> GraphBuild:  # noqa: B008
    """The navigation graph of ``vm``'s free space (see the module docstring)."""
    fs = build_free_space(vm, cfg.free_space)
    need = cfg.clearance_m
    graph_ok = (fs.clearance() >= need) & (fs.region >= 0)
    skel = thin(graph_ok)
    walls = WallIndex(vm.segments)
    b = _Builder(fs, walls, cfg)
    reps, branches = _branches(skel, fs, cfg)
    ids = {c: b.node(p) for c, p in reps.items()}
    for a, c, pts in branches:
        b.polyline(pts, ids[a], ids[c])
    # Regions whose skeleton vanished (a blob a few cells across): one node at the widest cell.
    have = set(fs.region_at(np.asarray(b.xy)).tolist()) if b.xy else set()
    for r in range(fs.n_regions):
        if r in have:
            continue
        sel = graph_ok & (fs.region == r)
        if sel.any():
            k = int(np.argmax(np.where(sel, fs.dist, -1.0)))
            b.node(fs.centres(np.array(k // fs.shape[1]), np.array(k % fs.shape[1])))
    _lattice(b, fs, graph_ok, cfg, dominant_angle(vm.segments))
    _cover(b, fs, graph_ok, cfg, rounds=2)
    _simplify(b, cfg)
    return _finish(b, fs, cfg)


def _finish(b: _Builder, fs: FreeSpace, cfg: GraphBuildConfig) -> GraphBuild:
    xy = np.round(np.asarray(b.xy, dtype=np.float64).reshape(-1, 2), 3)
    ij = np.array(list(b.edges.keys()), dtype=np.int64).reshape(-1, 2)
    clear = np.array(list(b.edges.values()), dtype=np.float64)
    # Nodes that no edge uses are kept only when their region has no other node.
    deg = np.bincount(ij.ravel(), minlength=len(xy))
    region = fs.region_at(xy)
    keep = deg > 0
    for r in np.unique(region[~keep]):
        if r >= 0 and not np.any(keep & (region == r)):
            keep[np.flatnonzero(~keep & (region == r))[0]] = True
    new_id = np.cumsum(keep) - 1
    xy, region = xy[keep], region[keep]
    ij = new_id[ij]
    # each edge's own exact clearance (a piece of a chained run may clear more than the run)
    clear = b.walls.clearances(np.concatenate([xy[ij[:, 0]], xy[ij[:, 1]]], axis=1), 5.0)
    comp = graph_components(len(xy), ij)
    nodes = tuple(NavNode(int(i), float(x), float(y)) for i, (x, y) in enumerate(xy))
    edges = []
    for (i, j), c in zip(ij, clear, strict=True):
        door = c < cfg.door_clearance_m
        edges.append(NavEdge(int(i), int(j), has_door=bool(door), max_speed=cfg.door_speed_mps if door else DEFAULT_MAX_SPEED,
                             max_clearance=round(float(c), 3)))
    graph = NavGraph(nodes, tuple(edges))
    narrow = tuple(r for r in range(fs.n_regions) if not np.any(region == r))
    split = tuple(int(r) for r in range(fs.n_regions) if np.unique(comp[region == r]).size > 1)
    return GraphBuild(graph, fs, region.astype(np.int64), comp, narrow, split)


# --------------------------------------------------------------------------- cache


#: Bumped when the construction changes, so that cached graphs of the old one are rebuilt.
GENERATOR_VERSION = 2


def graph_key(vm: VectorMap, cfg: GraphBuildConfig) -> str:
    """Hash of the walls, the settings and the generator version (the cache key)."""
    h = hashlib.sha256()
    h.update(f"v{GENERATOR_VERSION}".encode())
    h.update(np.ascontiguousarray(vm.segments, dtype=np.float64).tobytes())
    h.update(cfg.key().encode())
    return h.hexdigest()


@dataclass(frozen=True)
class CachedGraph:
    """A graph from :func:`cached_navgraph`, with where it is kept and whether it was made."""

    graph: NavGraph
    """The navigation graph."""
    path: Path | None
    """The cache file holding it (None when no place was writable)."""
    built: bool
    """Made now (True) or read from the cache (False)."""


def cached_navgraph(
    vm: VectorMap, map_path: str | os.PathLike[str] | None, cfg: GraphBuildConfig = GraphBuildConfig()  # noqa: B008
) -> CachedGraph:
    """The automatic graph of ``vm``, cached as ``<map file>.auto.navigation.json`` (or under
    ``~/.cache/depthnav``) with the key in a ``"depthnav"`` entry the format's readers
    ignore. A stale, foreign or corrupt cache file is rebuilt, never an error."""
    key = graph_key(vm, cfg)
    paths = cache_paths(map_path, key, ".auto.navigation.json")
    for p in paths:
        if not p.is_file():
            continue
        try:
            text = p.read_text(encoding="utf-8")
            if json.loads(text).get("depthnav", {}).get("key") != key:
                continue
            return CachedGraph(parse_navgraph_json(text, str(p)), p, False)
        except (OSError, ValueError, AttributeError):
            continue
    graph = build_navgraph(vm, cfg).graph
    text = with_key(format_navgraph_json(graph), key)
    for p in cache_paths(map_path, key, ".auto.navigation.json", for_writing=True):
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(text, encoding="utf-8")
            return CachedGraph(graph, p, True)
        except OSError:
            continue
    return CachedGraph(graph, None, True)


def load_or_build_navgraph(
    vm: VectorMap, map_path: str | os.PathLike[str] | None, cfg: GraphBuildConfig = GraphBuildConfig()  # noqa: B008
) -> NavGraph:
    """The graph of :func:`cached_navgraph`."""
    return cached_navgraph(vm, map_path, cfg).graph


def with_key(text: str, key: str) -> str:
    """A navigation.json text with the generator's cache key as a ``"depthnav"`` entry."""
    head = '{\n  "depthnav": ' + json.dumps({"generator": "autonomy.maps.graph_builder", "key": key}) + ","
    assert text.startswith("{\n")
    return head + text[1:]
