"""A building from its walls alone: scenarios and the env on a vector map without a
navigation graph or zones (the graph made from the walls, furniture in the free space,
starts, goals, waypoints and people in the graph's largest connected component)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.common.geometry import point_segment_distance
from autonomy.maps.graph_builder import graph_components
from autonomy.maps.planner import adjacency
from autonomy.maps.vectormap import VectorMap, save_vectormap
from autonomy.navigation.avoidance import AvoidanceConfig
from sim.experiments.runner import run_scenario
from sim.experiments.site import load_building
from sim.experiments.waypoints import plan_mission
from sim.scenario import MissionConfig, load_scenario
from sim.simulator import blueprints
from sim.simulator.building import (
    EDGE_CLEARANCE_M,
    WALL_CLEARANCE_M,
    Building,
    navgraph_from_walls,
    random_furniture,
    random_people,
)
from tests.helpers import GL

ROOT = Path(__file__).resolve().parents[2]
RADIUS = 0.3

#: A 12 x 6 m box split by a wall into a U (a corridor over a room, joined at the east
#: end), and beside it a closed 3 x 3 m room without a door: the graph made from these
#: walls has two connected components.
TWO_PARTS = np.array(
    [
        [0, 0, 12, 0], [12, 0, 12, 6], [12, 6, 0, 6], [0, 6, 0, 0], [0, 3, 9, 3],
        [14, 0, 17, 0], [17, 0, 17, 3], [17, 3, 14, 3], [14, 3, 14, 0],
    ],
    dtype=np.float64,
)


def _two_parts(tmp_path: Path) -> Building:
    vm = VectorMap.from_segments(TWO_PARTS, name="two_parts")
    path = save_vectormap(vm, tmp_path / "two_parts.vectormap.txt")
    return Building(vm, navgraph_from_walls(vm, path, AvoidanceConfig(robot_radius_m=RADIUS), quiet=True), map_path=path)


def _in_closed_room(xy: np.ndarray) -> np.ndarray:
    xy = np.atleast_2d(xy)
    return xy[:, 0] > 13.0


def _office_walls(tmp_path: Path) -> Path:
    """The walls (only) of a small generated office floor."""
    bp = blueprints.generate_building(blueprints.BuildingConfig(width_m=30.0, height_m=24.0, name="walls_only"), 5)
    return save_vectormap(bp.vectormap, tmp_path / "walls_only.vectormap.txt")


def _scenario(tmp_path: Path, map_file: str, extra: str = "") -> Path:
    p = tmp_path / "own.toml"
    p.write_text(
        f'name = "own"\ndescription = "t"\nseed = 4\n[map]\nvectormap = "{map_file}"\n'
        "[actors]\nrandom_furniture = 4\nrandom_people = 2\n"
        "[mission]\nn_random_waypoints = 3\nmax_duration_s = 4.0\n"
        "[report]\nfigures = false\nprogress = false\n" + extra
    )
    return p


# -- the graph is made, cached and used ---------------------------------------------------


def test_a_scenario_with_only_a_vectormap_loads_a_made_graph(tmp_path: Path, capsys) -> None:
    _office_walls(tmp_path)
    scn = load_scenario(_scenario(tmp_path, "walls_only.vectormap.txt"))
    assert scn.map.navgraph == ""
    b = load_building(scn)
    err = capsys.readouterr().err.strip().splitlines()
    cache = tmp_path / "walls_only.vectormap.txt.auto.navigation.json"
    assert cache.is_file()
    assert len(err) == 1 and "walls_only.vectormap.txt" in err[0] and str(cache) in err[0], err
    assert b.navgraph.n_nodes > 20 and not b.furniture_zones
    # The second time it is read from the cache, silently, and is the same graph.
    again = load_building(scn)
    assert capsys.readouterr().err == ""
    np.testing.assert_array_equal(again.navgraph.node_xy(), b.navgraph.node_xy())
    # A given navgraph still wins.
    scn2 = load_scenario(_scenario(tmp_path, "walls_only.vectormap.txt", ""), [f'map.navgraph="{cache.name}"'])
    assert load_building(scn2).navgraph.n_nodes == b.navgraph.n_nodes


def test_map_keys_are_checked(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"map\.navgraph: give it with 'vectormap'"):
        load_scenario(_scenario(tmp_path, "x.txt"), ['map.vectormap=""', 'map.name="small_floor"', 'map.navgraph="g.json"'])
    with pytest.raises(InputError, match=r"key 'map\.vectormap': file not found"):
        load_scenario(_scenario(tmp_path, "missing.vectormap.txt"))


def test_map_free_space_declares_a_map_open_or_closed(tmp_path: Path) -> None:
    """``[map] free_space``: TWO_PARTS closed (as told from its walls, which enclose two
    insides) is the U and the doorless room; declared open, everything within the walls'
    convex hull is free, so the 2 m strip between the two boxes becomes a third part."""
    save_vectormap(VectorMap.from_segments(TWO_PARTS, name="two_parts"), tmp_path / "two_parts.vectormap.txt")
    parts = {}
    for kind in ("auto", "closed", "open"):
        scn = load_scenario(_scenario(tmp_path, "two_parts.vectormap.txt"), [f'map.free_space="{kind}"'])
        b = load_building(scn)
        labels = graph_components(b.navgraph.n_nodes, b.navgraph.edge_indices())
        fs = b.free_space(RADIUS)
        parts[kind] = (int(labels.max()) + 1, fs.is_open)
        if kind == "open":
            x = b.navgraph.node_xy()[:, 0]
            assert ((x > 12.0) & (x < 14.0)).any()
    assert parts["auto"] == parts["closed"] == (2, False)
    assert parts["open"] == (3, True)
    with pytest.raises(InputError, match=r"map\.free_space 'ajar': expected one of auto, open, closed"):
        load_scenario(_scenario(tmp_path, "two_parts.vectormap.txt"), ['map.free_space="ajar"'])
    with pytest.raises(InputError, match=r"map\.free_space: only a map given as 'vectormap'"):
        load_scenario(_scenario(tmp_path, "x.txt"), ['map.vectormap=""', 'map.name="small_floor"', 'map.free_space="open"'])


@pytest.mark.slow
def test_a_scenario_with_only_a_vectormap_runs_headless(tmp_path: Path) -> None:
    _office_walls(tmp_path)
    scn = load_scenario(_scenario(tmp_path, "walls_only.vectormap.txt"))
    rep = run_scenario(scn, tmp_path / "out", progress=False)
    m = rep["metrics"]
    assert not rep["interrupted"] and m["frames"] > 0 and m["distance_m"] > 0.5
    assert m["collisions"] == 0 and m["resets"] == 0
    assert (tmp_path / "out" / "report.json").is_file()


# -- furniture in the free space ------------------------------------------------------------


def test_random_furniture_without_zones_is_clear_of_walls_and_edges(tmp_path: Path) -> None:
    vm = blueprints.generate_building(blueprints.BuildingConfig(width_m=30.0, height_m=24.0), 5).vectormap
    b = Building(vm, navgraph_from_walls(vm, tmp_path / "m.vectormap.txt", AvoidanceConfig(robot_radius_m=RADIUS), quiet=True))
    pieces = random_furniture(b, 8, np.random.default_rng(1), RADIUS)
    assert len(pieces) == 8
    walls, edges = np.asarray(vm.segments), b.navgraph.edge_segments()
    fs = b.free_space(RADIUS)
    for f in pieces:
        half = 0.5 * math.hypot(f.dims[0], f.dims[1])
        p = np.array([f.x, f.y])
        assert point_segment_distance(p, walls).min() >= half + WALL_CLEARANCE_M
        assert point_segment_distance(p, edges).min() >= half + RADIUS + EDGE_CLEARANCE_M
        assert fs.region_at(p) == 0
    # The same seed places them the same; the free space is made once per building.
    assert random_furniture(b, 8, np.random.default_rng(1), RADIUS) == pieces
    assert b.free_space(RADIUS) is fs


def test_a_building_pickles_without_its_caches(tmp_path: Path) -> None:
    import pickle

    b = _two_parts(tmp_path)
    b.free_space(RADIUS)
    _ = b.main_node_ids
    clone = pickle.loads(pickle.dumps(b))
    assert clone._free == {} and clone._main is None
    np.testing.assert_array_equal(clone.main_node_ids, b.main_node_ids)


# -- the largest connected component ----------------------------------------------------------


def test_starts_goals_waypoints_and_people_come_from_the_main_component(tmp_path: Path) -> None:
    from sim.envs.config import EnvConfig
    from sim.envs.task import sample_task

    b = _two_parts(tmp_path)
    g = b.navgraph
    comp = graph_components(g.n_nodes, g.edge_indices())
    assert comp.max() == 1 and _in_closed_room(g.node_xy()[comp == 1]).all()
    assert not _in_closed_room(g.node_xy()[comp == 0]).any()
    main = set(b.main_node_ids.tolist())
    for seed in range(20):
        rng = np.random.default_rng(seed)
        mission = plan_mission(MissionConfig(n_random_waypoints=4), g, rng)
        assert set(mission.waypoints) <= main and set(mission.pool) == main
        assert not _in_closed_room(mission.start_pose[:2]).any()
        for person in random_people(g, 2, rng, b.main_node_ids):
            assert not _in_closed_room(np.array(person.route)).any()
        site = SimpleNamespace(building=b, adj=adjacency(g))
        start, goal, goal_node = sample_task(EnvConfig(min_goal_distance_m=1.0), site, rng)
        assert goal_node in main and not _in_closed_room(start[:2]).any() and not _in_closed_room(goal).any()
    # random_people on a bare graph keeps to the main component as well.
    for person in random_people(g, 5, np.random.default_rng(0)):
        assert not _in_closed_room(np.array(person.route)).any()


def test_a_start_or_waypoint_outside_the_mission_component_is_a_one_line_error(tmp_path: Path) -> None:
    b = _two_parts(tmp_path)
    g = b.navgraph
    ids = g.node_ids()
    room = int(ids[_in_closed_room(g.node_xy())][0])
    main = int(b.main_node_ids[0])
    rng = np.random.default_rng(0)
    with pytest.raises(InputError, match=rf"mission\.start_node: node id {room} is not in .* largest") as exc:
        plan_mission(MissionConfig(start_node=room), g, rng)
    assert "\n" not in str(exc.value)
    with pytest.raises(InputError, match=rf"mission\.waypoints: node id {room} cannot be reached from node {main}"):
        plan_mission(MissionConfig(waypoints=(main, room)), g, rng)


# -- bad maps ---------------------------------------------------------------------------


def _no_room_map(tmp_path: Path) -> Path:
    """Walls enclosing nothing the robot fits in: a closed 5 x 0.5 m box."""
    vm = VectorMap.from_segments(np.array([[0, 0, 5, 0], [5, 0, 5, 0.5], [5, 0.5, 0, 0.5], [0, 0.5, 0, 0]], float))
    return save_vectormap(vm, tmp_path / "tiny.vectormap.txt")


def test_a_map_without_room_for_the_robot_exits_2_with_one_line(tmp_path: Path) -> None:
    _no_room_map(tmp_path)
    scn = _scenario(tmp_path, "tiny.vectormap.txt")
    r = subprocess.run(
        [sys.executable, "-m", "sim.cli", "run", str(scn), "--out", str(tmp_path / "out")],
        capture_output=True, text=True, cwd=ROOT,
    )
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith("depthnav: error:") and "fits a robot of radius 0.30 m" in lines[0]


def test_the_env_on_a_map_without_room_for_the_robot_is_a_one_line_error(tmp_path: Path) -> None:
    from sim.envs.depthnav import DepthNavEnv

    with pytest.raises(InputError, match="fits a robot of radius") as exc:
        DepthNavEnv(building="", vectormap=str(_no_room_map(tmp_path)))
    assert "\n" not in str(exc.value)


# -- the env ------------------------------------------------------------------------------


@pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")
def test_the_env_resets_and_steps_on_a_map_of_walls_only(tmp_path: Path) -> None:
    import gymnasium as gym

    import sim  # noqa: F401  (registers DepthNav-v0)

    path = _office_walls(tmp_path)
    env = gym.make("DepthNav-v0", building="", vectormap=str(path), n_furniture=3, n_people=2, max_steps=5)
    try:
        obs, info = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        site = env.unwrapped.site
        assert (tmp_path / "walls_only.vectormap.txt.auto.navigation.json").is_file()
        walls = np.asarray(site.building.vectormap.segments)
        for f in site.furniture:
            assert point_segment_distance(np.array([f.x, f.y]), walls).min() >= 0.5 * math.hypot(*f.dims[:2])
        for _ in range(3):
            obs, r, term, trunc, info = env.step(env.action_space.sample())
        assert np.isfinite(r)
        with pytest.raises(InputError, match=r"'start_pose' \(-5, -5, 0\) is outside the building's free space") as exc:
            env.reset(options={"start_pose": (-5.0, -5.0, 0.0)})
        assert "\n" not in str(exc.value)
    finally:
        env.close()
