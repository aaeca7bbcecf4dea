"""The env's simulated site: a compiled building reused across episodes (dm_control's ``Physics``).

A :class:`Site` holds the MuJoCo world of one building, its camera and its ray-cast
query. Between episodes the random furniture is moved and the people re-routed in place,
so a building is compiled once however many episodes it serves. :class:`SiteSchedule`
says which building each episode runs in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import mujoco
import numpy as np

from autonomy.common.errors import InputError
from autonomy.maps.planner import adjacency
from autonomy.maps.raycast import SceneQuery, VisibilityGrid, load_or_build
from autonomy.maps.vectormap import load_navgraph, load_vectormap
from sim.envs.config import EnvConfig
from sim.simulator import blueprints
from sim.simulator.actors import (
    PARK_XY,
    Furniture,
    PeopleController,
    Person,
    furniture_body,
    parked_person,
)
from sim.simulator.blueprints import ASSETS_DIR
from sim.simulator.building import (
    FURNITURE_KINDS,
    Building,
    navgraph_from_walls,
    random_people,
    replace_furniture,
)
from sim.simulator.kinect import KinectCamera, KinectConfig
from sim.simulator.world import World, build_world

#: A random person starts at least this far beyond both radii from the robot's start.
START_CLEARANCE_M = 0.5


def load_fixed_building(cfg: EnvConfig) -> Building | None:
    """The fixed building of a config (None when buildings are drawn per episode)."""
    if cfg.building == "procedural":
        if cfg.building_seed < 0:
            return None
        return procedural_building(cfg, cfg.building_seed)
    if cfg.vectormap:
        for key in ("vectormap", "navgraph"):
            if getattr(cfg, key) and not Path(getattr(cfg, key)).is_file():
                raise InputError(f"DepthNav: argument '{key}' expected an existing file, got {getattr(cfg, key)!r}")
        vm = load_vectormap(cfg.vectormap)
        graph = load_navgraph(cfg.navgraph) if cfg.navgraph else navgraph_from_walls(vm, cfg.vectormap, cfg.avoidance)
        b = Building(vm, graph, map_path=Path(cfg.vectormap))
    else:
        stem = cfg.building
        for suffix in (".vectormap.txt", ".navigation.json", ".zones.json"):
            stem = stem.removesuffix(suffix)
        shipped = ASSETS_DIR / f"{stem}.vectormap.txt"
        path = shipped if "/" not in stem and shipped.is_file() else Path(stem + ".vectormap.txt")
        if not path.is_file():
            names = ", ".join(sorted(p.name.removesuffix(".vectormap.txt") for p in ASSETS_DIR.glob("*.vectormap.txt")))
            raise InputError(
                f"DepthNav: argument 'building' expected a shipped building ({names}), a blueprint "
                f"stem path or 'procedural', got {cfg.building!r}"
            )
        bp = blueprints.load_blueprint(str(path).removesuffix(".vectormap.txt"))
        b = Building(bp.vectormap, bp.navgraph, tuple(bp.open_areas), tuple(bp.rooms), path)
    check_building(cfg, b)
    return b


def procedural_building(cfg: EnvConfig, seed: int) -> Building:
    bp = blueprints.generate_building(cfg.procedural, int(seed))
    return Building(bp.vectormap, bp.navgraph, tuple(bp.open_areas), tuple(bp.rooms))


def check_building(cfg: EnvConfig, b: Building) -> None:
    g = b.navgraph
    if g.n_edges < 1 or len(b.main_node_ids) < 2:
        raise InputError("DepthNav: the building's navigation graph needs at least two connected nodes")
    ids = {int(i) for i in g.node_ids()}
    for name in ("start_nodes", "goal_nodes"):
        for i in getattr(cfg, name):
            if i not in ids:
                raise InputError(f"DepthNav: argument '{name}' expected node ids of the navigation graph, got {i}")


def _yaw_quat(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


@dataclass
class Site:
    """A compiled building: the world, its camera, and what the episodes reuse."""

    building: Building
    world: World
    camera: KinectCamera
    adj: list[list[tuple[int, float]]]
    walls: np.ndarray
    furniture: list[Furniture]
    """Every piece; the first len(cfg.furniture) are fixed, the rest are re-placed."""
    furniture_bodies: np.ndarray
    mocap_ids: np.ndarray
    query: SceneQuery | None
    people: list[Person]
    seed: int | None = None
    canvas: object | None = None
    """The rgb_array view's background (a sim.envs.render.MapCanvas), drawn at the first render."""

    @classmethod
    def build(cls, cfg: EnvConfig, kinect: KinectConfig, building: Building, seed: int | None) -> Site:
        """Compile a building with room for the config's furniture and people."""
        # Kinds from the building's own seed, not the episode's: a fixed building is
        # compiled at the first reset only, and every reset must draw the same.
        rng = np.random.default_rng(0 if seed is None else seed)
        furniture = list(cfg.furniture) + [
            Furniture(kind=str(FURNITURE_KINDS[rng.integers(len(FURNITURE_KINDS))]), x=PARK_XY[0] - 10.0 * i, y=PARK_XY[1])
            for i in range(cfg.n_furniture)
        ]
        people = list(cfg.people) + [parked_person() for _ in range(cfg.n_people)]
        world = build_world(
            building.vectormap, world=cfg.world, robot=cfg.robot, intrinsics=kinect.intrinsics, mount=kinect.mount,
            furniture=tuple(furniture), people=tuple(people),
        )
        bodies = np.array(
            [mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_BODY, furniture_body(i)) for i in range(len(furniture))], dtype=np.int64
        )
        query = None
        if cfg.localization.enabled:
            vm = building.vectormap
            grid = (
                load_or_build(vm, building.map_path, cfg.localization.grid)
                if building.map_path is not None
                else VisibilityGrid.build(vm, cfg.localization.grid)
            )
            query = SceneQuery(vm, grid)
        return cls(
            building=building,
            world=world,
            camera=KinectCamera(world.model, world.camera_id, kinect),
            adj=adjacency(building.navgraph),
            walls=np.ascontiguousarray(building.vectormap.segments, dtype=np.float64).reshape(-1, 4),
            furniture=furniture,
            furniture_bodies=bodies,
            mocap_ids=world.people.mocap_ids.copy(),
            query=query,
            people=people,
            seed=seed,
        )

    def place_furniture(self, cfg: EnvConfig, rng: np.random.Generator) -> None:
        """Re-place the random pieces as the scenario runner places them."""
        fixed = len(cfg.furniture)
        self.furniture = replace_furniture(self.building, self.furniture, fixed, rng, cfg.robot.radius_m, PARK_XY)
        model = self.world.model
        for k in range(fixed, len(self.furniture)):
            f, bid = self.furniture[k], self.furniture_bodies[k]
            model.body_pos[bid] = [f.x, f.y, 0.0]
            model.body_quat[bid] = _yaw_quat(f.yaw)

    def route_people(self, cfg: EnvConfig, rng: np.random.Generator) -> None:
        """New routes for the random people, drawn as the scenario runner draws them."""
        b = self.building
        routes = list(random_people(b.navgraph, cfg.n_people, rng, b.main_node_ids)) if cfg.n_people else []
        routes += [parked_person() for _ in range(cfg.n_people - len(routes))]
        self.people = list(cfg.people) + routes
        self._restart_people(cfg)

    def _restart_people(self, cfg: EnvConfig) -> None:
        self.world.people = PeopleController(tuple(self.people), self.mocap_ids, self.walls, robot_radius_m=cfg.robot.radius_m)

    def clear_start(self, cfg: EnvConfig, start_xy: np.ndarray, rng: np.random.Generator) -> None:
        """Move random people's start offsets until none touches the robot's start."""
        first = len(cfg.people)
        for _ in range(20):
            pos = self.world.people.positions()
            bad = [
                i
                for i in range(first, len(self.people))
                if math.hypot(*(pos[i, :2] - start_xy)) < cfg.robot.radius_m + self.people[i].radius_m + START_CLEARANCE_M
            ]
            if not bad:
                return
            for i in bad:
                self.people[i] = replace(self.people[i], start_offset_m=float(rng.uniform(0.0, 40.0)))
            self._restart_people(cfg)

    def check_start_pose(self, cfg: EnvConfig, start: np.ndarray) -> None:
        """A given start pose must be where the robot fits inside the building."""
        fs = self.building.free_space(cfg.robot.radius_m)
        if int(fs.region_at(start[:2])) < 0:
            pose = ", ".join(f"{v:g}" for v in start)
            raise InputError(
                f"DepthNav: reset option 'start_pose' ({pose}) is outside the building's free space "
                f"(no room there for a robot of radius {cfg.robot.radius_m:g} m inside the walls)"
            )

    def close(self) -> None:
        self.camera.close()


class SiteSchedule:
    """Which compiled building each episode runs in: the config's fixed building, compiled
    at the first reset, or procedural ones drawn from the env's ``np_random`` every
    ``new_building_every`` episodes (and at every seeded reset)."""

    def __init__(self, cfg: EnvConfig, kinect: KinectConfig) -> None:
        self.config = cfg
        self.kinect = kinect
        """The camera at the observation's size, compiled into every site."""
        self.fixed = load_fixed_building(cfg)
        """The building of every episode (None: procedural buildings are drawn)."""
        self.site: Site | None = None
        """The current site (None before the first reset and after close)."""
        self.episodes_on_site = 0

    def site_for_episode(self, rng: np.random.Generator, seeded: bool) -> Site:
        """The site of the next episode (``seeded``: the reset had a seed)."""
        cfg = self.config
        if self.fixed is not None:
            if self.site is None:
                self.site = Site.build(cfg, self.kinect, self.fixed, None)
            return self.site
        # Procedural, drawn from rng (from building_seeds when given): a seeded reset
        # always draws a new building.
        if self.site is None or seeded or self.episodes_on_site >= cfg.new_building_every:
            seeds = cfg.building_seeds
            seed = int(seeds[rng.integers(len(seeds))] if seeds else rng.integers(0, 2**31 - 1))
            if self.site is not None and self.site.seed == seed:
                self.episodes_on_site = 0
                return self.site
            b = procedural_building(cfg, seed)
            check_building(cfg, b)
            if self.site is not None:
                self.site.close()
            self.site = Site.build(cfg, self.kinect, b, seed)
            self.episodes_on_site = 0
        return self.site

    def count_episode(self) -> None:
        """An episode started on the current site."""
        self.episodes_on_site += 1

    def close(self) -> None:
        if self.site is not None:
            self.site.close()
            self.site = None
