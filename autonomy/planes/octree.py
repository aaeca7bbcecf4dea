"""Octree plane map (PlaneMap, Section II-A).

The root is a cube (40 m edge) split recursively into octants down to leaves of 0.625 m
(depth 6). A plane is identified by its centre point (the centroid of its inliers) and
its orientation, and lives in the leaf holding its centre; a leaf holds at most one
plane. Nodes are created only where planes arrive, and when a plane's centre falls
outside the root a new, twice as large root is put above the old one (the paper: "it's
always possible to create a root node, if one exceeds the space").

Two policies for a plane arriving in an occupied leaf (``OctreeConfig.policy``):

- ``overwrite`` (the paper): the new plane replaces the old one.
- ``merge`` (ours): if the two agree — normals within ``merge_angle_deg`` and each
  centre within ``merge_distance_m`` of the other plane — they are fused: normal and
  centre are the support-weighted means (support = inlier points seen so far), the
  boundary is the convex hull of both boundaries in the fused plane, observations add
  up. If they disagree, the better-supported plane stays (ties go to the newcomer).

Exports: JSON (lossless, :meth:`PlaneOctree.to_json` / :meth:`PlaneOctree.from_json`),
meshes of the plane patches (PLY / GLB / OBJ via trimesh, imported lazily), and plain
arrays for viewers (:meth:`PlaneOctree.patches`, :meth:`PlaneOctree.leaf_boxes`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from autonomy.common.errors import InputError, require_positive
from autonomy.planes.boundary import fan_triangles, hull_2d, lift_hull, to_plane_coords
from autonomy.planes.geometry import Plane

POLICIES = ("overwrite", "merge")


@dataclass(frozen=True)
class OctreeConfig:
    """Octree plane map parameters; defaults from PlaneMap, Section II-A."""

    root_edge_m: float = 40.0
    """Edge of the root cube (40 m)."""
    leaf_edge_m: float = 0.625
    """Edge of a leaf (0.625 m, depth 6); root_edge_m / leaf_edge_m must be a power of two."""
    centre: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Centre of the root cube in the world frame."""
    policy: str = "overwrite"
    """overwrite: a new plane replaces the leaf's (the paper); merge: fuse agreeing planes (ours)."""
    merge_angle_deg: float = 10.0
    """merge: largest angle between the normals of planes that are fused."""
    merge_distance_m: float = 0.05
    """merge: largest distance of each plane's centre from the other plane for a fusion."""
    grow: bool = True
    """Put a larger root above the old one when a plane falls outside (else drop the plane)."""

    def __post_init__(self) -> None:
        require_positive(self, "octree.", "root_edge_m", "leaf_edge_m", "merge_angle_deg", "merge_distance_m")
        ratio = self.root_edge_m / self.leaf_edge_m
        depth = round(math.log2(ratio)) if ratio >= 1 else -1
        if depth < 0 or abs(2.0**depth - ratio) > 1e-9 * ratio:
            raise InputError(
                f"octree.leaf_edge_m: root_edge_m / leaf_edge_m must be a power of two, got {self.root_edge_m} / {self.leaf_edge_m}"
            )
        if self.policy not in POLICIES:
            raise InputError(f"octree.policy: expected one of {', '.join(POLICIES)}, got {self.policy!r}")
        if len(self.centre) != 3 or not all(math.isfinite(float(v)) for v in self.centre):
            raise InputError(f"octree.centre: expected three finite numbers, got {self.centre!r}")

    @property
    def depth(self) -> int:
        """Levels below the root (6 by default)."""
        return round(math.log2(self.root_edge_m / self.leaf_edge_m))


@dataclass
class MapPlane:
    """What a leaf holds: the plane (world frame) and its history."""

    plane: Plane
    """The plane: normal, rho, centre point, support and boundary."""
    support: int
    """Inlier points behind it (summed over fused observations)."""
    observations: int = 1
    """How many detections it stands for (1 unless fused)."""
    first_seen: int = 0
    """Frame (or stamp) of its first detection."""
    last_seen: int = 0
    """Frame (or stamp) of its latest detection."""
    source: str = ""
    """Free label, e.g. the detector (ransac / hough)."""

    def to_dict(self) -> dict:
        return {
            "plane": self.plane.to_dict(),
            "support": int(self.support),
            "observations": int(self.observations),
            "first_seen": int(self.first_seen),
            "last_seen": int(self.last_seen),
            "source": self.source,
        }


@dataclass(frozen=True)
class Leaf:
    """One occupied leaf: its box and its plane."""

    centre: np.ndarray
    """Centre of the leaf cube (3,)."""
    half_size: float
    """Half its edge."""
    entry: MapPlane
    """The plane it holds."""


@dataclass(frozen=True)
class PatchArrays:
    """The map's plane patches as triangle meshes, for viewers (rerun, trimesh)."""

    vertices: np.ndarray
    """(V, 3) float32 boundary vertices of all patches."""
    triangles: np.ndarray
    """(T, 3) int32 vertex indices (a fan per convex patch)."""
    triangle_patch: np.ndarray
    """(T,) int32 patch index of each triangle."""
    vertex_colors: np.ndarray
    """(V, 4) uint8 RGBA, a patch's colour on all its vertices."""
    normals: np.ndarray
    """(P, 3) unit normal of each patch."""
    colors: np.ndarray
    """(P, 4) uint8 RGBA of each patch (by normal direction)."""
    centres: np.ndarray
    """(P, 3) centre point of each patch."""


@dataclass
class InsertStats:
    """Counts of what happened to inserted planes."""

    inserted: int = 0
    """Planes put into an empty leaf."""
    overwritten: int = 0
    """Planes that replaced a leaf's plane (overwrite policy)."""
    merged: int = 0
    """Planes fused with a leaf's plane (merge policy)."""
    kept_old: int = 0
    """Disagreeing planes dropped because the leaf's plane was better supported (merge)."""
    replaced: int = 0
    """Disagreeing planes that replaced a less-supported leaf plane (merge)."""
    grown: int = 0
    """Times the root was replaced by a larger one."""
    outside: int = 0
    """Planes dropped outside a root that may not grow."""


def normal_color(n: np.ndarray) -> np.ndarray:
    """RGBA uint8 colour of a normal: |n| mapped to RGB (x red, y green, z blue)."""
    c = np.abs(np.asarray(n, dtype=np.float64))
    c = 0.25 + 0.75 * c / max(float(c.max()), 1e-9)
    return np.array([*(np.round(255 * c).astype(np.uint8)), 255], dtype=np.uint8)


class PlaneOctree:
    """Octree of planes: at most one per leaf, found by its centre point (Section II-A)."""

    def __init__(self, cfg: OctreeConfig = OctreeConfig()) -> None:
        self.cfg = cfg
        self.stats = InsertStats()
        self._leaf_half = cfg.leaf_edge_m / 2.0
        self._depth = cfg.depth
        self._root_centre = np.asarray(cfg.centre, dtype=np.float64).copy()
        self._root_half = cfg.root_edge_m / 2.0
        # Node arrays (lists): centre, half edge, children (8 ints, -1 = none).
        self._centres: list[np.ndarray] = [self._root_centre.copy()]
        self._halves: list[float] = [self._root_half]
        self._children: list[list[int]] = [[-1] * 8]
        self._root = 0
        self._leaves: dict[int, MapPlane] = {}

    # -- structure -------------------------------------------------------------------

    @property
    def depth(self) -> int:
        """Levels below the current root (grows with the root)."""
        return self._depth

    @property
    def root_edge_m(self) -> float:
        return 2.0 * self._root_half

    @property
    def root_centre(self) -> np.ndarray:
        return self._root_centre.copy()

    @property
    def n_leaves(self) -> int:
        """Occupied leaves (= planes in the map)."""
        return len(self._leaves)

    @property
    def n_nodes(self) -> int:
        """All nodes, root and leaves included."""
        return len(self._centres)

    def __len__(self) -> int:
        return len(self._leaves)

    def _new_node(self, centre: np.ndarray, half: float) -> int:
        self._centres.append(centre)
        self._halves.append(half)
        self._children.append([-1] * 8)
        return len(self._centres) - 1

    def contains(self, p: np.ndarray) -> bool:
        """Whether a point lies inside the current root cube."""
        return bool(np.all(np.abs(np.asarray(p, dtype=np.float64) - self._root_centre) <= self._root_half))

    def _grow_towards(self, p: np.ndarray) -> None:
        """A root twice as large, extended towards p; the old root becomes one of its children."""
        step = np.where(p >= self._root_centre, 1.0, -1.0)
        new_centre = self._root_centre + step * self._root_half
        new_half = 2.0 * self._root_half
        old = self._root
        new = self._new_node(new_centre, new_half)
        octant = int((self._root_centre[0] >= new_centre[0]) | ((self._root_centre[1] >= new_centre[1]) << 1) | ((self._root_centre[2] >= new_centre[2]) << 2))
        self._children[new][octant] = old
        self._root, self._root_centre, self._root_half = new, new_centre, new_half
        self._depth += 1
        self.stats.grown += 1

    def _leaf_for(self, p: np.ndarray, create: bool) -> int:
        """Node id of the leaf containing p (created on the way if ``create``), or -1."""
        node = self._root
        for _ in range(self._depth):
            c = self._centres[node]
            octant = int((p[0] >= c[0]) | ((p[1] >= c[1]) << 1) | ((p[2] >= c[2]) << 2))
            child = self._children[node][octant]
            if child < 0:
                if not create:
                    return -1
                h = self._halves[node] / 2.0
                off = np.array([h if octant & 1 else -h, h if octant & 2 else -h, h if octant & 4 else -h])
                child = self._new_node(c + off, h)
                self._children[node][octant] = child
            node = child
        return node

    def leaf_box(self, p: np.ndarray) -> tuple[np.ndarray, float]:
        """Centre and half edge of the leaf (existing or not) that would hold point p."""
        q = np.asarray(p, dtype=np.float64)
        lo = self._root_centre - self._root_half
        e = 2.0 * self._leaf_half
        i = np.floor((q - lo) / e)
        return lo + (i + 0.5) * e, self._leaf_half

    # -- insertion -------------------------------------------------------------------

    def insert(self, plane: Plane, stamp: int = 0, source: str = "") -> bool:
        """Register a world-frame plane at its centre point; False if it was dropped."""
        c = np.asarray(plane.centroid, dtype=np.float64)
        if c.shape != (3,) or not np.isfinite(c).all():
            raise InputError(f"octree.insert: plane centre must be 3 finite numbers, got {plane.centroid!r}")
        while not self.contains(c):
            if not self.cfg.grow:
                self.stats.outside += 1
                return False
            self._grow_towards(c)
        leaf = self._leaf_for(c, create=True)
        new = MapPlane(plane, int(plane.n_points), 1, stamp, stamp, source)
        old = self._leaves.get(leaf)
        if old is None:
            self._leaves[leaf] = new
            self.stats.inserted += 1
            return True
        if self.cfg.policy == "overwrite":
            self._leaves[leaf] = new
            self.stats.overwritten += 1
            return True
        if self.agree(old.plane, plane):
            self._leaves[leaf] = fuse(old, new)
            self.stats.merged += 1
            return True
        if new.support >= old.support:
            self._leaves[leaf] = new
            self.stats.replaced += 1
            return True
        self.stats.kept_old += 1
        return False

    def agree(self, a: Plane, b: Plane) -> bool:
        """Whether two planes are the same surface under the merge tolerances."""
        cos_ang = abs(float(a.normal @ b.normal))
        if cos_ang < math.cos(math.radians(self.cfg.merge_angle_deg)):
            return False
        d = self.cfg.merge_distance_m
        return abs(float(a.distance(b.centroid))) <= d and abs(float(b.distance(a.centroid))) <= d

    # -- queries ---------------------------------------------------------------------

    def leaves(self) -> Iterator[Leaf]:
        """Every occupied leaf, in creation order."""
        for node, entry in self._leaves.items():
            yield Leaf(self._centres[node].copy(), self._halves[node], entry)

    def __iter__(self) -> Iterator[Leaf]:
        return self.leaves()

    def planes(self) -> list[Plane]:
        """All planes in the map."""
        return [e.plane for e in self._leaves.values()]

    def at(self, p: np.ndarray) -> MapPlane | None:
        """The plane of the leaf containing point p, if any."""
        q = np.asarray(p, dtype=np.float64)
        if not self.contains(q):
            return None
        leaf = self._leaf_for(q, create=False)
        return self._leaves.get(leaf) if leaf >= 0 else None

    def query_box(self, lo: np.ndarray, hi: np.ndarray) -> list[Leaf]:
        """Occupied leaves whose cube intersects the axis-aligned box [lo, hi]."""
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        if lo.shape != (3,) or hi.shape != (3,) or np.any(hi < lo):
            raise InputError("octree.query_box: expected lo and hi 3-vectors with lo <= hi")
        out: list[Leaf] = []
        stack = [self._root]
        while stack:
            node = stack.pop()
            c, h = self._centres[node], self._halves[node]
            if np.any(c + h < lo) or np.any(c - h > hi):
                continue
            if node in self._leaves:
                out.append(Leaf(c.copy(), h, self._leaves[node]))
            stack.extend(ch for ch in self._children[node] if ch >= 0)
        return out

    def query_sphere(self, centre: np.ndarray, radius: float) -> list[Leaf]:
        """Occupied leaves whose cube comes within ``radius`` of ``centre``."""
        q = np.asarray(centre, dtype=np.float64)
        box = self.query_box(q - radius, q + radius)
        return [lf for lf in box if float(np.linalg.norm(np.maximum(np.abs(lf.centre - q) - lf.half_size, 0.0))) <= radius]

    def leaf_boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """Occupied leaves as boxes: centres (L, 3) and half sizes (L, 3)."""
        nodes = list(self._leaves)
        if not nodes:
            return np.zeros((0, 3)), np.zeros((0, 3))
        centres = np.array([self._centres[n] for n in nodes])
        halves = np.repeat(np.array([[self._halves[n]] for n in nodes]), 3, axis=1)
        return centres, halves

    def node_boxes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every node as a box: centres (M, 3), half sizes (M, 3), depth below the root (M,)."""
        depth = np.zeros(self.n_nodes, dtype=np.int32)
        stack = [(self._root, 0)]
        seen = []
        while stack:
            node, d = stack.pop()
            depth[node] = d
            seen.append(node)
            stack.extend((ch, d + 1) for ch in self._children[node] if ch >= 0)
        seen.sort()
        centres = np.array([self._centres[n] for n in seen])
        halves = np.repeat(np.array([[self._halves[n]] for n in seen]), 3, axis=1)
        return centres, halves, depth[seen]

    def size(self) -> dict[str, float]:
        """Map size: planes, nodes, boundary vertices, root edge, depth, bytes of JSON."""
        return {
            "planes": self.n_leaves,
            "nodes": self.n_nodes,
            "boundary_vertices": int(sum(len(e.plane.hull) for e in self._leaves.values())),
            "root_edge_m": self.root_edge_m,
            "depth": self._depth,
            "json_bytes": len(json.dumps(self.to_json(), separators=(",", ":"))),
        }

    # -- export ----------------------------------------------------------------------

    def patches(self) -> PatchArrays:
        """All plane patches as one triangle mesh (a fan per boundary polygon)."""
        verts, tris, tri_patch, vcol, normals, colors, centres = [], [], [], [], [], [], []
        base = 0
        for k, entry in enumerate(self._leaves.values()):
            p = entry.plane
            col = normal_color(p.normal)
            normals.append(p.normal)
            colors.append(col)
            centres.append(p.centroid)
            hull = p.hull
            if len(hull) < 3:
                continue
            # Wind each fan so that its face normal matches the plane's normal.
            t = fan_triangles(len(hull))
            e = np.cross(hull[1] - hull[0], hull[2] - hull[0])
            if float(e @ p.normal) < 0:
                t = t[:, ::-1]
            verts.append(hull)
            tris.append(t + base)
            tri_patch.append(np.full(len(t), k, dtype=np.int32))
            vcol.append(np.repeat(col[None], len(hull), axis=0))
            base += len(hull)
        if not verts:
            return PatchArrays(
                np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32), np.zeros(0, np.int32),
                np.zeros((0, 4), np.uint8), np.array(normals).reshape(-1, 3), np.array(colors, np.uint8).reshape(-1, 4),
                np.array(centres).reshape(-1, 3),
            )
        return PatchArrays(
            np.concatenate(verts).astype(np.float32),
            np.concatenate(tris).astype(np.int32),
            np.concatenate(tri_patch),
            np.concatenate(vcol),
            np.array(normals),
            np.array(colors, dtype=np.uint8),
            np.array(centres),
        )

    def export_mesh(self, path: str | Path) -> Path:
        """Write the plane patches as a mesh: .ply, .glb or .obj (by extension; trimesh)."""
        path = Path(path)
        ext = path.suffix.lower()
        if ext not in (".ply", ".glb", ".obj"):
            raise InputError(f"{path}: expected a .ply, .glb or .obj mesh file name")
        import trimesh

        pa = self.patches()
        mesh = trimesh.Trimesh(vertices=pa.vertices, faces=pa.triangles, vertex_colors=pa.vertex_colors, process=False)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            mesh.export(path)
        except OSError as exc:
            raise InputError(f"{path}: cannot write the mesh: {exc.strerror or exc}") from None
        return path

    def to_json(self) -> dict:
        """The whole map as JSON-able data (lossless; see :meth:`from_json`)."""
        cfg = self.cfg
        return {
            "format": "depthnav.plane_octree",
            "version": 1,
            "config": {
                "root_edge_m": cfg.root_edge_m,
                "leaf_edge_m": cfg.leaf_edge_m,
                "centre": list(cfg.centre),
                "policy": cfg.policy,
                "merge_angle_deg": cfg.merge_angle_deg,
                "merge_distance_m": cfg.merge_distance_m,
                "grow": cfg.grow,
            },
            "root": {"centre": [float(v) for v in self._root_centre], "edge_m": self.root_edge_m, "depth": self._depth},
            "leaves": [
                {"centre": [float(v) for v in lf.centre], "half_size_m": lf.half_size, **lf.entry.to_dict()}
                for lf in self.leaves()
            ],
        }

    @classmethod
    def from_json(cls, data: dict, source: str = "octree") -> PlaneOctree:
        """Rebuild a map from :meth:`to_json` output (InputError naming ``source`` if malformed)."""
        try:
            if data.get("format") != "depthnav.plane_octree":
                raise InputError(f"{source}: key 'format': expected 'depthnav.plane_octree'")
            c = data["config"]
            cfg = OctreeConfig(
                root_edge_m=float(c["root_edge_m"]),
                leaf_edge_m=float(c["leaf_edge_m"]),
                centre=tuple(float(v) for v in c["centre"]),
                policy=str(c["policy"]),
                merge_angle_deg=float(c["merge_angle_deg"]),
                merge_distance_m=float(c["merge_distance_m"]),
                grow=bool(c["grow"]),
            )
            tree = cls(cfg)
            root = data["root"]
            tree._root_centre = np.asarray(root["centre"], dtype=np.float64)
            tree._root_half = float(root["edge_m"]) / 2.0
            tree._depth = int(root["depth"])
            tree._centres[0] = tree._root_centre.copy()
            tree._halves[0] = tree._root_half
            if abs(tree._root_half * 2.0 / 2.0**tree._depth - cfg.leaf_edge_m) > 1e-9:
                raise InputError(f"{source}: key 'root': edge_m / 2^depth must equal leaf_edge_m")
            for i, lf in enumerate(data["leaves"]):
                centre = np.asarray(lf["centre"], dtype=np.float64)
                if not tree.contains(centre):
                    raise InputError(f"{source}: key 'leaves[{i}].centre': outside the root cube")
                node = tree._leaf_for(centre, create=True)
                tree._leaves[node] = MapPlane(
                    Plane.from_dict(lf["plane"], f"{source}: leaves[{i}].plane"),
                    int(lf["support"]),
                    int(lf["observations"]),
                    int(lf["first_seen"]),
                    int(lf["last_seen"]),
                    str(lf.get("source", "")),
                )
        except InputError:
            raise
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise InputError(f"{source}: not a plane octree map ({type(exc).__name__}: {exc})") from None
        return tree

    def save_json(self, path: str | Path) -> Path:
        """Write :meth:`to_json` to a file."""
        path = Path(path)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(self.to_json(), indent=1) + "\n", encoding="utf-8")
        except OSError as exc:
            raise InputError(f"{path}: cannot write the map: {exc.strerror or exc}") from None
        return path

    @classmethod
    def load_json(cls, path: str | Path) -> PlaneOctree:
        """Read a map written by :meth:`save_json`."""
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise InputError(f"{path}: map file not found") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: not a JSON file: {exc}") from None
        if not isinstance(data, dict):
            raise InputError(f"{path}: expected a JSON object")
        return cls.from_json(data, str(path))


def fuse(old: MapPlane, new: MapPlane) -> MapPlane:
    """Support-weighted fusion of two agreeing planes (the merge policy)."""
    a, b = old.plane, new.plane
    wa, wb = float(old.support), float(new.support)
    s = 1.0 if float(a.normal @ b.normal) >= 0 else -1.0
    n = wa * a.normal + wb * s * b.normal
    n /= np.linalg.norm(n)
    c = (wa * a.centroid + wb * b.centroid) / (wa + wb)
    rho = float(n @ c)
    pts = [h for h in (a.hull, b.hull) if len(h)]
    if pts:
        allp = np.vstack(pts)
        h2 = hull_2d(to_plane_coords(allp, n, rho, c))
        hull = lift_hull(h2, n, rho, c)
    else:
        hull = np.zeros((0, 3))
    rms = math.sqrt((wa * a.rms_m**2 + wb * b.rms_m**2) / (wa + wb))
    plane = Plane(n, rho, c, int(a.n_points + b.n_points), rms, hull)
    return MapPlane(plane, old.support + new.support, old.observations + new.observations, old.first_seen, new.last_seen, old.source or new.source)
