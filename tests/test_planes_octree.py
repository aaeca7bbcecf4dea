"""Octree plane map (PlaneMap, II-A): placement, policies, growth, queries, exports."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.planes import (
    OctreeConfig,
    Plane,
    PlaneOctree,
    RansacConfig,
    detection_frame,
    plane_basis,
    pose_transform,
    ransac_planes,
    register_planes,
)


def square_plane(normal, centre, half=0.2, n_points=1000) -> Plane:
    """A square patch of the plane through ``centre`` with normal ``normal``."""
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    c = np.asarray(centre, dtype=np.float64)
    u, v = plane_basis(n)
    hull = np.array([c + half * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return Plane(n, float(n @ c), c, n_points, 0.002, hull)


def leaf_centre_brute(p, root_centre=(0, 0, 0), root_edge=40.0, leaf=0.625) -> np.ndarray:
    lo = np.asarray(root_centre, dtype=np.float64) - root_edge / 2
    return lo + (np.floor((np.asarray(p) - lo) / leaf) + 0.5) * leaf


def test_default_geometry_is_the_papers() -> None:
    cfg = OctreeConfig()
    assert (cfg.root_edge_m, cfg.leaf_edge_m, cfg.depth, cfg.policy) == (40.0, 0.625, 6, "overwrite")


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"leaf_edge_m": 0.6}, "power of two"),
        ({"leaf_edge_m": 80.0}, "power of two"),
        ({"policy": "keep"}, "octree.policy"),
        ({"root_edge_m": -1.0}, "octree.root_edge_m"),
        ({"centre": (0.0, float("nan"), 0.0)}, "octree.centre"),
    ],
)
def test_bad_config(kw, match) -> None:
    with pytest.raises(InputError, match=match):
        OctreeConfig(**kw)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(*[st.floats(-19.9, 19.9).map(lambda x: round(x, 6))] * 3), min_size=1, max_size=40))
def test_planes_land_in_the_right_leaves(centres) -> None:
    tree = PlaneOctree()
    for c in centres:
        tree.insert(square_plane([0, 0, 1], c))
    expect = {tuple(leaf_centre_brute(c)) for c in centres}
    got_c, got_h = tree.leaf_boxes()
    assert len(got_c) == len(expect)
    for c, h in zip(got_c, got_h, strict=True):
        assert np.allclose(h, 0.3125)
        assert any(np.allclose(c, e, atol=1e-9) for e in expect)
    for c in centres:
        entry = tree.at(c)
        assert entry is not None
        lc, _ = tree.leaf_box(c)
        np.testing.assert_allclose(lc, leaf_centre_brute(c), atol=1e-9)
        # The leaf's plane is the last one inserted there (overwrite).
        last = [q for q in centres if np.allclose(leaf_centre_brute(q), lc)][-1]
        np.testing.assert_allclose(entry.plane.centroid, last)
    assert tree.n_nodes <= 1 + 6 * len(centres)


def test_overwrite_policy_replaces() -> None:
    tree = PlaneOctree(OctreeConfig(policy="overwrite"))
    a = square_plane([1, 0, 0], [1.1, 1.1, 1.1], n_points=5000)
    b = square_plane([0, 1, 0], [1.2, 1.2, 1.2], n_points=10)
    assert tree.insert(a, 1) and tree.insert(b, 2)
    assert tree.n_leaves == 1 and tree.stats.overwritten == 1
    e = tree.at([1.0, 1.0, 1.0])
    assert e.plane is b and e.first_seen == 2


def test_merge_policy_fuses_agreeing_planes() -> None:
    tree = PlaneOctree(OctreeConfig(policy="merge"))
    a = square_plane([1, 0, 0], [1.1, 1.1, 1.1], half=0.1, n_points=3000)
    n_b = np.array([1.0, math.tan(math.radians(4)), 0.0])
    b = square_plane(-n_b, [1.11, 1.2, 1.2], half=0.1, n_points=1000)  # opposite sign, 4 degrees off
    tree.insert(a, 1)
    tree.insert(b, 2)
    e = tree.at([1.1, 1.1, 1.1])
    assert tree.stats.merged == 1 and e.observations == 2 and e.support == 4000
    assert (e.first_seen, e.last_seen) == (1, 2)
    # Support-weighted mean of the normals (b flipped to a's side) and of the centres.
    ref = 3000 * a.normal + 1000 * (-b.normal)
    np.testing.assert_allclose(e.plane.normal, ref / np.linalg.norm(ref))
    np.testing.assert_allclose(e.plane.centroid, (3000 * a.centroid + 1000 * b.centroid) / 4000)
    assert e.plane.rho == pytest.approx(float(e.plane.normal @ e.plane.centroid))
    # The fused boundary lies on the fused plane and covers both patches' extents.
    np.testing.assert_allclose(e.plane.distance(e.plane.hull), 0.0, atol=1e-9)
    assert np.ptp(e.plane.hull[:, 1]) > 0.25 and np.ptp(e.plane.hull[:, 2]) > 0.25


def test_merge_policy_keeps_the_better_supported_on_disagreement() -> None:
    tree = PlaneOctree(OctreeConfig(policy="merge"))
    strong = square_plane([1, 0, 0], [1.1, 1.1, 1.1], n_points=5000)
    tree.insert(strong)
    assert not tree.insert(square_plane([0, 1, 0], [1.1, 1.1, 1.1], n_points=100))
    assert tree.at([1.1, 1.1, 1.1]).plane is strong and tree.stats.kept_old == 1
    offset = square_plane([1, 0, 0], [1.2, 1.1, 1.1], n_points=9000)  # parallel, 10 cm away
    assert tree.insert(offset)
    assert tree.at([1.1, 1.1, 1.1]).plane is offset and tree.stats.replaced == 1


def test_root_grows_to_take_planes_outside() -> None:
    tree = PlaneOctree()
    inside = square_plane([0, 0, 1], [1.0, 2.0, 0.5])
    tree.insert(inside)
    far = square_plane([0, 0, 1], [35.0, -70.0, 0.5])
    assert tree.insert(far)
    assert tree.depth >= 8 and tree.stats.grown >= 2
    assert tree.contains(far.centroid) and tree.contains(inside.centroid)
    assert tree.at(inside.centroid).plane is inside and tree.at(far.centroid).plane is far
    c, h = tree.leaf_boxes()
    assert np.allclose(h, 0.3125)
    # Leaves stay on the original root's grid.
    for p in (inside.centroid, far.centroid):
        assert any(np.allclose(leaf_centre_brute(p), x) for x in c)
    fixed = PlaneOctree(OctreeConfig(grow=False))
    assert not fixed.insert(far) and fixed.stats.outside == 1 and fixed.n_leaves == 0


@settings(max_examples=25, deadline=None)
@given(
    st.lists(st.tuples(*[st.floats(-19, 19)] * 3), min_size=0, max_size=30),
    st.tuples(*[st.floats(-20, 20)] * 3),
    st.tuples(*[st.floats(0, 10)] * 3),
)
def test_query_box_matches_brute_force(centres, lo, size) -> None:
    tree = PlaneOctree()
    for c in centres:
        tree.insert(square_plane([0, 1, 0], c))
    lo = np.array(lo)
    hi = lo + np.array(size)
    got = {tuple(np.round(lf.centre, 9)) for lf in tree.query_box(lo, hi)}
    want = set()
    for lf in tree.leaves():
        if np.all(lf.centre + lf.half_size >= lo) and np.all(lf.centre - lf.half_size <= hi):
            want.add(tuple(np.round(lf.centre, 9)))
    assert got == want
    for lf in tree.query_sphere(lo, 2.0):
        assert np.linalg.norm(np.maximum(np.abs(lf.centre - lo) - lf.half_size, 0)) <= 2.0


def _sample_tree(policy: str) -> PlaneOctree:
    rng = np.random.default_rng(3)
    tree = PlaneOctree(OctreeConfig(policy=policy))
    for k in range(60):
        n = rng.normal(size=3)
        tree.insert(square_plane(n, rng.uniform(-5, 5, 3), half=rng.uniform(0.05, 0.5), n_points=int(rng.integers(100, 5000))), k, "test")
    tree.insert(square_plane([0, 0, 1], [30.0, 0.0, 0.0]), 99)  # grows the root
    return tree


@pytest.mark.parametrize("policy", ["overwrite", "merge"])
def test_json_round_trip(tmp_path, policy) -> None:
    tree = _sample_tree(policy)
    data = tree.to_json()
    back = PlaneOctree.from_json(json.loads(json.dumps(data)))
    assert back.to_json() == data
    assert back.depth == tree.depth and back.n_leaves == tree.n_leaves
    path = tree.save_json(tmp_path / "m" / "map.json")
    again = PlaneOctree.load_json(path)
    assert again.to_json() == data
    # Inserting into the loaded map behaves as in the original.
    p = square_plane([1, 0, 0], [0.1, 0.1, 0.1])
    assert again.insert(p) == tree.insert(p)
    assert again.to_json() == tree.to_json()


def test_bad_json_is_an_input_error(tmp_path) -> None:
    with pytest.raises(InputError, match="not found"):
        PlaneOctree.load_json(tmp_path / "none.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{", encoding="utf-8")
    with pytest.raises(InputError, match="not a JSON file"):
        PlaneOctree.load_json(bad)
    bad.write_text(json.dumps({"format": "other"}), encoding="utf-8")
    with pytest.raises(InputError, match="format"):
        PlaneOctree.load_json(bad)
    data = _sample_tree("overwrite").to_json()
    del data["leaves"][0]["plane"]["rho"]
    with pytest.raises(InputError, match=r"leaves\[0\]"):
        PlaneOctree.from_json(data)


def test_patches_and_mesh_export(tmp_path) -> None:
    import trimesh

    tree = _sample_tree("overwrite")
    pa = tree.patches()
    n = tree.n_leaves
    assert pa.normals.shape == (n, 3) and pa.colors.shape == (n, 4) and pa.centres.shape == (n, 3)
    assert pa.vertices.shape[0] == pa.vertex_colors.shape[0] == 4 * n
    assert pa.triangles.shape == (2 * n, 3) and pa.triangle_patch.shape == (2 * n,)
    # Each triangle faces along its patch's normal.
    v = pa.vertices[pa.triangles].astype(np.float64)
    fn = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    assert np.all(np.einsum("ij,ij->i", fn, pa.normals[pa.triangle_patch]) > 0)
    c, h = tree.leaf_boxes()
    assert c.shape == h.shape == (n, 3)
    nc, nh, nd = tree.node_boxes()
    assert len(nc) == tree.n_nodes and nd.max() == tree.depth
    for ext in (".ply", ".glb", ".obj"):
        out = tree.export_mesh(tmp_path / f"map{ext}")
        mesh = trimesh.load(out, force="mesh", process=False)
        assert len(mesh.faces) == 2 * n
    with pytest.raises(InputError, match="mesh file name"):
        tree.export_mesh(tmp_path / "map.stl")
    assert PlaneOctree().patches().vertices.shape == (0, 3)
    size = tree.size()
    assert size["planes"] == n and size["json_bytes"] > 0


def test_register_planes_moves_detections_to_the_world() -> None:
    from autonomy.perception.camera import ROBOT_FROM_OPTICAL_LEVEL

    rng = np.random.default_rng(0)
    # Camera 0.8 m up looking to the robot's right; robot at (5, 3) facing +y, so the
    # camera looks along world +x at a wall 2 m away: the world wall x = 7.
    r_from_c = np.eye(4)
    r_from_c[:3, :3] = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ ROBOT_FROM_OPTICAL_LEVEL
    r_from_c[:3, 3] = [0.0, 0.0, 0.8]
    u = rng.uniform(-0.8, 0.8, (20000, 2))
    optical = np.column_stack([u[:, 0], u[:, 1], 2.0 + rng.normal(0, 0.002, len(u))])
    rot, w_from_s = detection_frame(np.array([5.0, 3.0, math.pi / 2]), r_from_c)
    det = ransac_planes(optical @ rot.T, RansacConfig(), 0)
    # In the detection frame (world axes, sensor origin) the wall is x = 2.
    assert abs(det.planes[0].normal @ [1, 0, 0]) > math.cos(math.radians(1)) and abs(det.planes[0].rho - 2.0) < 0.01
    tree = PlaneOctree()
    assert register_planes(tree, det, w_from_s, stamp=4, source="ransac") == 1
    (leaf,) = list(tree.leaves())
    p = leaf.entry.plane
    assert abs(p.normal @ [1, 0, 0]) > math.cos(math.radians(1))
    assert abs(abs(p.rho) - 7.0) < 0.01
    np.testing.assert_allclose(p.centroid, [7.0, 3.0, 0.8], atol=0.05)
    assert leaf.entry.source == "ransac" and leaf.entry.last_seen == 4
    # The same through pose_transform: world_from_sensor is the camera's position.
    np.testing.assert_allclose(w_from_s[:3, 3], (pose_transform(5.0, 3.0, math.pi / 2) @ r_from_c)[:3, 3])
