"""Navigation graphs (UT AMRL ``*.navigation.json``) and their file format.

``{"nodes": [{"id", "loc": {"x", "y"}}], "edges": [{"s0_id", "s1_id", "has_door",
"has_stairs", "has_elevator", "has_automated_door", "max_speed", "max_clearance"}]}``;
an edge's flags and limits are optional (false, :data:`DEFAULT_MAX_SPEED`,
:data:`DEFAULT_MAX_CLEARANCE`). Every malformed input raises
:class:`autonomy.maps.map_files.MapFormatError`, whose one-line message names the file,
the line and the element path (e.g. ``edges[3].s1_id``) and what was expected.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from autonomy.maps.map_files import (
    PathLike,
    _json_load,
    _json_type,
    _JsonCtx,
    _read_text,
    _readonly,
)

DEFAULT_MAX_SPEED = 0.75
"""Default edge speed limit in m/s when a file leaves it out."""
DEFAULT_MAX_CLEARANCE = 1.0
"""Default edge clearance in metres when a file leaves it out."""


def _finite_float(v: Any, what: str) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected a number, got {v!r}") from None
    if not math.isfinite(f):
        raise InputError(f"{what}: expected a finite number, got {v!r}")
    return f


@dataclass(frozen=True)
class NavNode:
    """A navigation-graph vertex."""

    id: int
    """Node id (unique in its graph; not necessarily contiguous)."""
    x: float
    """World x in metres."""
    y: float
    """World y in metres."""

    def __post_init__(self) -> None:
        if isinstance(self.id, bool) or not isinstance(self.id, int | np.integer):
            raise InputError(f"nav node: id must be an integer, got {self.id!r}")
        object.__setattr__(self, "id", int(self.id))
        object.__setattr__(self, "x", _finite_float(self.x, f"nav node {self.id} x"))
        object.__setattr__(self, "y", _finite_float(self.y, f"nav node {self.id} y"))


@dataclass(frozen=True)
class NavEdge:
    """An undirected navigation-graph edge between two node ids."""

    s0_id: int
    """First node id."""
    s1_id: int
    """Second node id."""
    has_door: bool = False
    """The edge passes through a doorway."""
    has_stairs: bool = False
    """The edge uses stairs."""
    has_elevator: bool = False
    """The edge uses an elevator."""
    has_automated_door: bool = False
    """The edge passes an automated door."""
    max_speed: float = DEFAULT_MAX_SPEED
    """Speed limit on this edge in m/s."""
    max_clearance: float = DEFAULT_MAX_CLEARANCE
    """Free half-width either side of the edge in metres."""

    def __post_init__(self) -> None:
        for k in ("s0_id", "s1_id"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, int | np.integer):
                raise InputError(f"nav edge: {k} must be an integer, got {v!r}")
            object.__setattr__(self, k, int(v))
        for k in ("has_door", "has_stairs", "has_elevator", "has_automated_door"):
            object.__setattr__(self, k, bool(getattr(self, k)))
        for k in ("max_speed", "max_clearance"):
            v = _finite_float(getattr(self, k), f"nav edge {self.s0_id}-{self.s1_id} {k}")
            if v < 0:
                raise InputError(f"nav edge {self.s0_id}-{self.s1_id} {k}: must be >= 0, got {v}")
            object.__setattr__(self, k, v)


_EDGE_FLAGS = ("has_door", "has_stairs", "has_elevator", "has_automated_door")


@dataclass(frozen=True)
class NavGraph:
    """An undirected navigation graph (UT AMRL ``*.navigation.json``)."""

    nodes: tuple[NavNode, ...]
    """Vertices, in file order."""
    edges: tuple[NavEdge, ...] = ()
    """Undirected edges between node ids."""
    _index: dict[int, int] = field(init=False, repr=False, compare=False)
    _adj: tuple[tuple[int, ...], ...] = field(init=False, repr=False, compare=False)
    _xy: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        nodes = tuple(self.nodes)
        edges = tuple(self.edges)
        if not nodes:
            raise InputError("nav graph: no nodes")
        index: dict[int, int] = {}
        for i, n in enumerate(nodes):
            if not isinstance(n, NavNode):
                raise InputError(f"nav graph: nodes[{i}] is not a NavNode")
            if n.id in index:
                raise InputError(f"nav graph: nodes[{i}] duplicates node id {n.id} (first at nodes[{index[n.id]}])")
            index[n.id] = i
        adj: list[list[int]] = [[] for _ in nodes]
        for j, e in enumerate(edges):
            if not isinstance(e, NavEdge):
                raise InputError(f"nav graph: edges[{j}] is not a NavEdge")
            for k in ("s0_id", "s1_id"):
                if getattr(e, k) not in index:
                    raise InputError(f"nav graph: edges[{j}].{k} names unknown node id {getattr(e, k)}")
            a, b = index[e.s0_id], index[e.s1_id]
            adj[a].append(e.s1_id)
            if a != b:
                adj[b].append(e.s0_id)
        xy = np.array([(n.x, n.y) for n in nodes], dtype=np.float64).reshape(-1, 2)
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "edges", edges)
        object.__setattr__(self, "_index", index)
        object.__setattr__(self, "_adj", tuple(tuple(a) for a in adj))
        object.__setattr__(self, "_xy", _readonly(xy))

    @property
    def n_nodes(self) -> int:
        """Number of nodes."""
        return len(self.nodes)

    @property
    def n_edges(self) -> int:
        """Number of edges."""
        return len(self.edges)

    def node_xy(self) -> np.ndarray:
        """(N, 2) node positions in node order (read-only)."""
        return self._xy

    def node_ids(self) -> np.ndarray:
        """(N,) node ids in node order."""
        return np.array([n.id for n in self.nodes], dtype=np.int64)

    def index_of(self, node_id: int) -> int:
        """Position of a node id in :attr:`nodes`; InputError if unknown."""
        try:
            return self._index[int(node_id)]
        except (KeyError, TypeError, ValueError):
            raise InputError(f"nav graph: unknown node id {node_id!r}") from None

    def node(self, node_id: int) -> NavNode:
        """The node with this id."""
        return self.nodes[self.index_of(node_id)]

    def neighbors(self, node_id: int) -> list[int]:
        """Ids of the nodes joined to ``node_id`` by an edge, in edge order."""
        return list(self._adj[self.index_of(node_id)])

    def nearest_node(self, x: float, y: float) -> int:
        """Id of the node closest to ``(x, y)``."""
        d2 = (self._xy[:, 0] - x) ** 2 + (self._xy[:, 1] - y) ** 2
        return self.nodes[int(np.argmin(d2))].id

    def edge_indices(self) -> np.ndarray:
        """(E, 2) int64 node *indices* (positions in :attr:`nodes`) of each edge."""
        return np.array(
            [(self._index[e.s0_id], self._index[e.s1_id]) for e in self.edges], dtype=np.int64
        ).reshape(-1, 2)

    def edge_segments(self) -> np.ndarray:
        """(E, 4) edges as segments ``x1, y1, x2, y2``."""
        ij = self.edge_indices()
        return np.concatenate([self._xy[ij[:, 0]], self._xy[ij[:, 1]]], axis=1).reshape(-1, 4)

    def __repr__(self) -> str:
        return f"NavGraph(n_nodes={self.n_nodes}, n_edges={self.n_edges})"

    def edge_lengths(self) -> np.ndarray:
        """(E,) edge lengths in metres."""
        s = self.edge_segments()
        return np.hypot(s[:, 2] - s[:, 0], s[:, 3] - s[:, 1])


def parse_navgraph_json(text: str, source: str = "<string>") -> NavGraph:
    """Parse a UT AMRL navigation graph (``{"nodes": [...], "edges": [...]}``)."""
    data = _json_load(text, source)
    ctx = _JsonCtx(text, source)
    top = ctx.obj(data, [], 'an object {"nodes": [...], "edges": [...]}')
    raw_nodes = ctx.key(top, "nodes", [])
    raw_edges = ctx.key(top, "edges", [])
    if not isinstance(raw_nodes, list):
        raise ctx.fail(["nodes"], f"expected an array of nodes, got {_json_type(raw_nodes)}")
    if not isinstance(raw_edges, list):
        raise ctx.fail(["edges"], f"expected an array of edges, got {_json_type(raw_edges)}")
    if not raw_nodes:
        raise ctx.fail(["nodes"], "expected at least one node, got an empty array")
    nodes: list[NavNode] = []
    first: dict[int, int] = {}
    for i, rn in enumerate(raw_nodes):
        p: list[int | str] = ["nodes", i]
        d = ctx.obj(rn, p, 'a node object {"id": int, "loc": {"x": .., "y": ..}}')
        nid = ctx.integer(ctx.key(d, "id", p), p + ["id"])
        loc = ctx.obj(ctx.key(d, "loc", p), p + ["loc"], 'a point object {"x": .., "y": ..}')
        x = ctx.number(ctx.key(loc, "x", p + ["loc"]), p + ["loc", "x"])
        y = ctx.number(ctx.key(loc, "y", p + ["loc"]), p + ["loc", "y"])
        if nid in first:
            raise ctx.fail(p + ["id"], f"duplicate node id {nid} (first at nodes[{first[nid]}])")
        first[nid] = i
        nodes.append(NavNode(nid, x, y))
    edges: list[NavEdge] = []
    for j, re_ in enumerate(raw_edges):
        p = ["edges", j]
        d = ctx.obj(re_, p, 'an edge object {"s0_id": int, "s1_id": int, ...}')
        ids = []
        for k in ("s0_id", "s1_id"):
            v = ctx.integer(ctx.key(d, k, p), p + [k])
            if v not in first:
                raise ctx.fail(p + [k], f"unknown node id {v} (edge {j} must join existing nodes)")
            ids.append(v)
        kw: dict[str, Any] = {}
        for k in _EDGE_FLAGS:
            if k in d:
                kw[k] = ctx.boolean(d[k], p + [k])
        for k in ("max_speed", "max_clearance"):
            if k in d:
                v = ctx.number(d[k], p + [k])
                if v < 0:
                    raise ctx.fail(p + [k], f"expected a number >= 0, got {v!r}")
                kw[k] = v
        edges.append(NavEdge(ids[0], ids[1], **kw))
    return NavGraph(tuple(nodes), tuple(edges))


def format_navgraph_json(g: NavGraph) -> str:
    """JSON text of a navigation graph, one node / edge per line, repr-exact floats."""
    node_rows = [
        json.dumps({"id": n.id, "loc": {"x": n.x, "y": n.y}}) for n in g.nodes
    ]
    edge_rows = [
        json.dumps(
            {
                "s0_id": e.s0_id,
                "s1_id": e.s1_id,
                "has_door": e.has_door,
                "has_stairs": e.has_stairs,
                "has_elevator": e.has_elevator,
                "has_automated_door": e.has_automated_door,
                "max_speed": e.max_speed,
                "max_clearance": e.max_clearance,
            }
        )
        for e in g.edges
    ]

    def block(rows: list[str]) -> str:
        return "[\n    " + ",\n    ".join(rows) + "\n  ]" if rows else "[]"

    return '{\n  "nodes": ' + block(node_rows) + ',\n  "edges": ' + block(edge_rows) + "\n}\n"


def load_navgraph(path: PathLike) -> NavGraph:
    """Load a ``*.navigation.json`` file."""
    text, source = _read_text(path)
    return parse_navgraph_json(text, source)


def save_navgraph(g: NavGraph, path: PathLike) -> Path:
    """Write a navigation graph as JSON; returns the path."""
    p = Path(path)
    p.write_text(format_navgraph_json(g), encoding="utf-8")
    return p
