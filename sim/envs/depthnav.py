"""Gymnasium environment ``DepthNav-v0``: point-goal navigation with a Kinect-model depth camera.

:class:`EnvConfig` holds every parameter; :class:`DepthNavEnv` (registered as
``DepthNav-v0`` by ``import sim``) documents the action and observation spaces, rewards,
episode ends, info, seeding and rendering. docs/env.md has examples.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import typing
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from autonomy.camera import CameraIntrinsics
from autonomy.cgr import CGRLocalizer
from autonomy.errors import InputError
from autonomy.fspf import FSPFConfig, FSPFResult, fspf
from autonomy.planner import adjacency
from autonomy.raycast import SceneQuery, VisibilityGrid, load_or_build
from autonomy.vectormap import load_navgraph, load_vectormap
from sim.envs.geometry import GeodesicField, KCScanner
from sim.envs.render import (
    ESTIMATE,
    FRUSTUM,
    FURNITURE,
    GOAL,
    PARTICLE,
    PATH,
    PERSON,
    ROBOT,
    MapCanvas,
    depth_to_rgb,
    draw_disk,
    draw_points,
    draw_segments,
    fill_convex,
)
from sim.experiments.runner import Building, random_people
from sim.scenario import ASSETS_DIR, LocalizationConfig, load_scenario
from sim.simulator import blueprints
from sim.simulator.actors import Furniture, PeopleController, Person, point_segment_distance
from sim.simulator.kinect import KinectCamera, KinectConfig
from sim.simulator.robot import Odometry, OdometryConfig, RobotConfig, relative_pose
from sim.simulator.world import World, WorldConfig, build_world

ENV_ID = "DepthNav-v0"

#: Bound of the ``goal`` observation (metres); values beyond are clipped.
GOAL_LIMIT_M = 1000.0
#: Bound of positions in ``pose_estimate`` (metres).
POSITION_LIMIT_M = 1.0e4
#: Depth beyond the GL far plane cannot occur (sim.simulator.world sets it at 60 m).
FAR_PLANE_M = 60.0
#: Where unused furniture and people are parked (outside any building).
_PARK_XY = (-1.0e4, -1.0e4)
RENDER_MODES = ("rgb_array", "depth")
REWARD_TERMS = ("progress", "success", "collision", "time")

#: True in a process forked from one that had already opened an EGL display: Mesa's
#: renderer threads do not survive fork(), and rendering there would hang for ever.
_GL_INHERITED = False


def _after_fork_in_child() -> None:
    global _GL_INHERITED
    egl = sys.modules.get("mujoco.egl")
    if egl is not None and getattr(egl, "EGL_DISPLAY", None) is not None:
        _GL_INHERITED = True


os.register_at_fork(after_in_child=_after_fork_in_child)


def _default_procedural() -> blueprints.BuildingConfig:
    return blueprints.BuildingConfig(width_m=30.0, height_m=24.0, name="procedural")


@dataclass(frozen=True)
class EnvConfig:
    """Everything about a DepthNav environment: building, actors, episodes, rewards, sensors.

    Pass fields as keyword arguments to ``gymnasium.make("DepthNav-v0", ...)`` or to
    :class:`DepthNavEnv`; :meth:`from_scenario` fills them from a scenario file.
    """

    # -- the building ---------------------------------------------------------------
    building: str = "small_floor"
    """A shipped building (sim/assets: small_floor, corridor_loop), a blueprint file stem
    (``path/name`` with name.vectormap.txt, .navigation.json, .zones.json), 'procedural',
    or '' when ``vectormap`` and ``navgraph`` are given."""
    vectormap: str = ""
    """A vector-map file (text or JSON); with ``navgraph`` and ``building=''``."""
    navgraph: str = ""
    """The navigation-graph file that goes with ``vectormap``."""
    procedural: blueprints.BuildingConfig = field(default_factory=_default_procedural)
    """Generator parameters for ``building='procedural'`` (default: 30 x 24 m floors)."""
    building_seed: int = -1
    """procedural: >= 0 fixes the building (a scenario's map.generate_seed); -1 draws
    buildings from np_random."""
    new_building_every: int = 1
    """procedural with building_seed -1: draw a new building every N episodes (a reset
    with a seed always draws one)."""
    # -- actors ---------------------------------------------------------------------
    furniture: tuple[Furniture, ...] = ()
    """Fixed furniture pieces (unmapped clutter)."""
    people: tuple[Person, ...] = ()
    """People walking fixed routes."""
    n_furniture: int = 0
    """Extra furniture pieces (kinds drawn per building) placed at random in the open
    areas (or rooms), clear of the navigation graph, every episode."""
    n_people: int = 0
    """Extra people walking random navigation-graph routes, redrawn every episode."""
    # -- episodes -------------------------------------------------------------------
    start_nodes: tuple[int, ...] = ()
    """Navigation-graph node ids to start at (empty: any node)."""
    goal_nodes: tuple[int, ...] = ()
    """Node ids to draw goals from (empty: any node)."""
    min_goal_distance_m: float = 2.0
    """Smallest geodesic start-goal distance drawn."""
    max_goal_distance_m: float = 0.0
    """Largest geodesic start-goal distance drawn (0: no limit)."""
    goal_radius_m: float = 0.5
    """Success when the true position is this close to the goal."""
    max_steps: int = 1000
    """Truncate an episode after this many steps (1000 frames = 33 s at 30 Hz)."""
    rrd: str = ""
    """Write a rerun recording of every step to this .rrd file (made lazily in the process
    that steps the env; in a vector env give each env its own file)."""
    rrd_every: int = 5
    """Log the heavy items (depth, FSPF points, particles) every Nth step."""
    terminate_on_success: bool = True
    """End the episode (terminated) on reaching the goal."""
    terminate_on_collision: bool = True
    """End the episode (terminated) on a collision."""
    # -- rewards --------------------------------------------------------------------
    progress_reward_per_m: float = 1.0
    """Reward per metre of geodesic progress towards the goal (negative when receding)."""
    success_reward: float = 10.0
    """Reward on reaching the goal (once per episode)."""
    collision_reward: float = -10.0
    """Reward per new collision."""
    time_reward: float = -0.01
    """Reward every step."""
    # -- observations ---------------------------------------------------------------
    depth_shape: tuple[int, int] = (120, 160)
    """(rows, columns) of the depth observation; same aspect ratio as kinect.intrinsics.
    The camera renders at this size directly (scaled intrinsics, same field of view)."""
    goal_from_truth: bool = False
    """Observe the goal relative to the true pose instead of the pose estimate."""
    observe_points: int = 0
    """> 0: add ``points``, this many FSPF points (padded, with a mask column)."""
    observe_scan: int = 0
    """> 0: add ``scan``, a KC-style laser scan with this many bins over the camera's
    horizontal field of view. More bins than depth columns leave empty bins (the paper's
    0.35 degrees is 165 bins, which needs depth_shape (480, 640))."""
    observe_pose_estimate: bool = False
    """Add ``pose_estimate`` (CGR mean and spread); needs localization.enabled."""
    scan_min_height_m: float = 0.1
    """Scan: lowest point height used (above the floor)."""
    scan_max_height_m: float = 2.0
    """Scan: highest point height used."""
    geodesic_radius_m: float = 8.0
    """Sight radius for the geodesic distance's straight legs (sim.envs.geometry)."""
    render_size: tuple[int, int] = (480, 640)
    """(rows, columns) of the rgb_array map view."""
    # -- simulation and the robot-side stack ----------------------------------------
    world: WorldConfig = field(default_factory=WorldConfig)
    """How the blueprint becomes a MuJoCo world."""
    robot: RobotConfig = field(default_factory=RobotConfig)
    """The omnidirectional base (speed limits scale the action)."""
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    """Odometry noise (20% by default, the paper's)."""
    kinect: KinectConfig = field(default_factory=KinectConfig)
    """The depth camera; its intrinsics are scaled to depth_shape, the noise model runs
    at that size (on one thread: the output does not depend on it)."""
    fspf: FSPFConfig = field(default_factory=FSPFConfig)
    """FSPF parameters for the full-size camera; eta_px is scaled to depth_shape."""
    localization: LocalizationConfig = field(default_factory=LocalizationConfig)
    """CGR localization (enabled by default); disabled: the estimate is dead reckoning.
    Above ``reset_error_m`` error the filter is re-initialised at the true pose and
    ``info['loc_resets']`` counts it."""

    def __post_init__(self) -> None:
        _check_types(self)

        def need(ok: bool, name: str, what: str) -> None:
            if not ok:
                raise InputError(f"DepthNav: argument '{name}' expected {what}, got {getattr(self, name)!r}")

        choices = sum([bool(self.building), bool(self.vectormap)])
        if choices != 1 or bool(self.vectormap) != bool(self.navgraph):
            raise InputError(
                "DepthNav: give exactly one of 'building' (a shipped name, a blueprint stem or "
                "'procedural') or 'vectormap' with 'navgraph' (and building='')"
            )
        need(self.new_building_every >= 1, "new_building_every", "an integer >= 1")
        need(self.building_seed >= -1, "building_seed", "an integer >= -1")
        need(self.n_furniture >= 0, "n_furniture", "an integer >= 0")
        need(self.n_people >= 0, "n_people", "an integer >= 0")
        need(self.min_goal_distance_m >= 0, "min_goal_distance_m", "a number >= 0")
        need(
            self.max_goal_distance_m == 0 or self.max_goal_distance_m >= self.min_goal_distance_m,
            "max_goal_distance_m",
            "0 (no limit) or a number >= min_goal_distance_m",
        )
        need(self.goal_radius_m > 0, "goal_radius_m", "a positive number")
        need(self.max_steps >= 1, "max_steps", "an integer >= 1")
        need(self.rrd_every >= 1, "rrd_every", "an integer >= 1")
        h, w = self.depth_shape
        need(h >= 8 and w >= 8, "depth_shape", "(rows, columns), each >= 8")
        intr = self.kinect.intrinsics
        need(
            h * intr.width == w * intr.height,
            "depth_shape",
            f"the camera's aspect ratio {intr.width}:{intr.height} as (rows, columns), e.g. (120, 160)",
        )
        need(self.observe_points >= 0, "observe_points", "an integer >= 0 (0: no 'points' key)")
        need(self.observe_scan >= 0, "observe_scan", "an integer >= 0 (0: no 'scan' key)")
        need(
            not self.observe_pose_estimate or self.localization.enabled,
            "observe_pose_estimate",
            "False when localization.enabled is False (there is no CGR estimate)",
        )
        need(self.scan_max_height_m > self.scan_min_height_m, "scan_max_height_m", "a height above scan_min_height_m")
        need(self.geodesic_radius_m > 0, "geodesic_radius_m", "a positive number")
        need(self.render_size[0] >= 32 and self.render_size[1] >= 32, "render_size", "(rows, columns), each >= 32")
        for name in ("start_nodes", "goal_nodes"):
            need(len(set(getattr(self, name))) == len(getattr(self, name)), name, "distinct node ids")

    def replace(self, **changes: Any) -> EnvConfig:
        """A copy with some fields changed; an unknown name is an InputError."""
        known = {f.name for f in fields(self)}
        for k in changes:
            if k not in known:
                raise InputError(f"DepthNav: unknown argument '{k}' (expected one of: {', '.join(sorted(known))})")
        return replace(self, **changes)

    @classmethod
    def from_scenario(cls, path: str | Path, overrides: list[str] | None = None, **changes: Any) -> EnvConfig:
        """The map, robot, sensors, stack, actors and mission limits of a scenario file.

        ``map`` picks the building (``generate_seed`` gives one fixed procedural building
        drawn with the generator's defaults, as the runner does); ``actors`` the furniture
        and people; ``mission.start_node`` and ``mission.waypoints`` restrict the start and
        goal nodes; ``mission.max_duration_s`` sets max_steps. The scenario's seed is not
        used: seed the env with ``reset(seed=...)``. ``changes`` are EnvConfig fields.
        """
        scn = load_scenario(path, overrides)
        m = scn.map
        where: dict[str, Any] = {}
        if m.generate_seed >= 0:
            where = dict(building="procedural", building_seed=m.generate_seed, procedural=blueprints.BuildingConfig())
        elif m.name:
            where = dict(building=m.name)
        else:
            where = dict(building="", vectormap=str(scn.resolve(m.vectormap)), navgraph=str(scn.resolve(m.navgraph)))
        base = cls(
            **where,
            furniture=tuple(scn.actors.furniture),
            people=tuple(scn.actors.people),
            n_furniture=scn.actors.random_furniture,
            n_people=scn.actors.random_people,
            start_nodes=(scn.mission.start_node,) if scn.mission.start_node >= 0 else (),
            goal_nodes=tuple(scn.mission.waypoints),
            max_steps=max(1, math.ceil(scn.mission.max_duration_s * scn.kinect.rate_hz - 1e-9)),
            world=scn.world,
            robot=scn.robot,
            odometry=scn.odometry,
            kinect=scn.kinect,
            fspf=scn.fspf,
            localization=scn.localization,
        )
        return base.replace(**changes)


def _type_ok(tp: Any, v: Any) -> tuple[bool, Any]:
    """(ok, normalised value) for the field types EnvConfig uses."""
    if tp is bool:
        return isinstance(v, bool | np.bool_), bool(v) if isinstance(v, bool | np.bool_) else v
    if tp is int:
        ok = isinstance(v, int | np.integer) and not isinstance(v, bool | np.bool_)
        return ok, int(v) if ok else v
    if tp is float:
        ok = isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool | np.bool_)
        ok = ok and math.isfinite(float(v))
        return ok, float(v) if ok else v
    if tp is str:
        if isinstance(v, Path):
            return True, str(v)
        return isinstance(v, str), v
    if typing.get_origin(tp) is tuple:
        if not isinstance(v, tuple | list):
            return False, v
        args = typing.get_args(tp)
        elem = [args[0]] * len(v) if len(args) == 2 and args[1] is Ellipsis else list(args)
        if len(elem) != len(v):
            return False, v
        out = []
        for a, x in zip(elem, v, strict=True):
            ok, x2 = _type_ok(a, x)
            if not ok:
                return False, v
            out.append(x2)
        return True, tuple(out)
    if dataclasses.is_dataclass(tp):
        return isinstance(v, tp), v
    raise TypeError(f"unsupported EnvConfig field type {tp!r}")  # a bug


_TYPE_NAMES = {bool: "True or False", int: "an integer", float: "a finite number", str: "a string"}


def _check_types(cfg: EnvConfig) -> None:
    hints = typing.get_type_hints(EnvConfig)
    for f in fields(cfg):
        tp = hints[f.name]
        v = getattr(cfg, f.name)
        ok, norm = _type_ok(tp, v)
        if not ok:
            if typing.get_origin(tp) is tuple:
                args = typing.get_args(tp)
                what = (
                    f"a tuple of {getattr(args[0], '__name__', args[0])}"
                    if len(args) == 2 and args[1] is Ellipsis
                    else f"a tuple of {len(args)} {getattr(args[0], '__name__', args[0])}s"
                )
            else:
                what = _TYPE_NAMES.get(tp, f"a {getattr(tp, '__name__', tp)}")
            raise InputError(f"DepthNav: argument '{f.name}' expected {what}, got {v!r}")
        if norm is not v:
            object.__setattr__(cfg, f.name, norm)


# --------------------------------------------------------------------------- buildings


def _load_building(cfg: EnvConfig) -> Building | None:
    """The fixed building of a config (None when buildings are drawn per episode)."""
    if cfg.building == "procedural":
        if cfg.building_seed < 0:
            return None
        return _procedural(cfg, cfg.building_seed)
    if cfg.vectormap:
        for key in ("vectormap", "navgraph"):
            if not Path(getattr(cfg, key)).is_file():
                raise InputError(f"DepthNav: argument '{key}' expected an existing file, got {getattr(cfg, key)!r}")
        b = Building(load_vectormap(cfg.vectormap), load_navgraph(cfg.navgraph), map_path=Path(cfg.vectormap))
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
    _check_building(cfg, b)
    return b


def _procedural(cfg: EnvConfig, seed: int) -> Building:
    bp = blueprints.generate_building(cfg.procedural, int(seed))
    return Building(bp.vectormap, bp.navgraph, tuple(bp.open_areas), tuple(bp.rooms))


def _check_building(cfg: EnvConfig, b: Building) -> None:
    g = b.navgraph
    if g.n_nodes < 2 or g.n_edges < 1:
        raise InputError("DepthNav: the building's navigation graph needs at least two connected nodes")
    ids = {int(i) for i in g.node_ids()}
    for name in ("start_nodes", "goal_nodes"):
        for i in getattr(cfg, name):
            if i not in ids:
                raise InputError(f"DepthNav: argument '{name}' expected node ids of the navigation graph, got {i}")
    if cfg.n_furniture and not (b.open_areas or b.rooms):
        raise InputError(
            "DepthNav: argument 'n_furniture' expected 0 for a map without zones (open areas or rooms), "
            f"got {cfg.n_furniture}"
        )


def _dijkstra(adj: list[list[tuple[int, float]]], src: int) -> np.ndarray:
    import heapq

    dist = np.full(len(adj), np.inf)
    dist[src] = 0.0
    heap = [(0.0, src)]
    while heap:
        d, u = heapq.heappop(heap)
        if d > dist[u]:
            continue
        for v, w in adj[u]:
            if d + w < dist[v]:
                dist[v] = d + w
                heapq.heappush(heap, (d + w, v))
    return dist


def _yaw_quat(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


@dataclass
class _Site:
    """A compiled building: the world, its renderer, and what the episodes reuse."""

    building: Building
    world: World
    camera: KinectCamera
    adj: list[list[tuple[int, float]]]
    walls: np.ndarray
    edges: np.ndarray
    furniture: list[Furniture]
    """Every piece; the first len(cfg.furniture) are fixed, the rest are re-placed."""
    furniture_bodies: np.ndarray
    mocap_ids: np.ndarray
    query: SceneQuery | None
    seed: int | None = None
    canvas: MapCanvas | None = None


# --------------------------------------------------------------------------- the env


class DepthNavEnv(gym.Env):
    """Point-goal navigation in an office building from Kinect depth (``DepthNav-v0``).

    The robot (an omnidirectional base, :mod:`sim.simulator.robot`) starts at a random node of a
    building's navigation graph and must reach a goal node drawn at a geodesic distance in
    ``[min_goal_distance_m, max_goal_distance_m]``. One env step is one camera frame
    (``1 / kinect.rate_hz`` s, 30 Hz by default): the action sets the velocity command,
    people walk, physics advances, a noisy depth frame is rendered at the observation size,
    odometry integrates, and (if enabled) FSPF and CGR localization run on the frame. The
    goal is observed in the robot frame of the pose *estimate* (CGR, or dead reckoning when
    localization is off), or of the true pose with ``goal_from_truth=True``.

    Buildings come from the shipped assets (``building="small_floor"``, the default, or
    ``"corridor_loop"``), from blueprint or vector-map files, from a scenario file
    (``scenario="scenarios/demo.toml"``), or from the procedural generator
    (``building="procedural"``: a new building from ``np_random`` every
    ``new_building_every`` episodes). A building's MuJoCo world is compiled once and reused
    across resets: furniture is moved and people are re-routed in place.

    ## Action space

    ``Box(-1, 1, (3,), float32)``, a body-frame velocity command scaled to the robot's limits
    (the translational speed is limited on the norm, and the change of the command by the
    acceleration limits, as :meth:`sim.simulator.robot.RobotHandle.command` does):

    | Num | Action | Min | Max | Scaled to |
    | --- | --- | --- | --- | --- |
    | 0 | forward velocity vx | -1 | 1 | ``robot.max_speed_mps`` (0.75 m/s) |
    | 1 | leftward velocity vy | -1 | 1 | ``robot.max_speed_mps`` |
    | 2 | yaw rate omega (counter-clockwise) | -1 | 1 | ``robot.max_angular_rad_s`` (1.5 rad/s) |

    ## Observation space

    A ``Dict`` of float32 boxes. Always present:

    | Key | Shape | Range | Meaning |
    | --- | --- | --- | --- |
    | ``depth`` | ``depth_shape`` (120, 160) | [0, max range (4 m)] | Kinect-model planar depth in metres (noise at this size), 0 = invalid |
    | ``goal`` | (2,) | [-1000, 1000] m | goal (x forward, y left) in the robot frame of the pose estimate (or of the true pose) |
    | ``odometry`` | (3,) | [-1, 1] m, [-pi, pi] rad | last noisy odometry increment (dx, dy, dtheta) in the previous robot frame; 0 after reset |

    Optional, chosen by constructor arguments:

    | Key | Argument | Shape | Meaning |
    | --- | --- | --- | --- |
    | ``points`` | ``observe_points=N`` | (N, 8) | FSPF points in the robot frame, one per row: x, y, z (m), normal nx, ny, nz (0 for outliers), ``plane`` (1 plane-filtered point, 0 outlier), ``valid`` (1 real point, 0 padding); plane points first, then outliers; a random subset when there are more than N |
    | ``scan`` | ``observe_scan=B`` | (B,) | KC-style laser scan: nearest return per azimuth bin over the camera's horizontal field of view (bin 0 rightmost), from the camera's floor position, points between ``scan_min_height_m`` and ``scan_max_height_m``; 0 = no return |
    | ``pose_estimate`` | ``observe_pose_estimate=True`` | (5,) | CGR estimate in the world frame: x, y (m, clipped to +-1e4), theta, position spread ``std_xy_m``, heading spread ``std_theta_rad`` |

    ## Rewards

    ``reward = progress + success + collision + time`` (exactly, in that order), each term in
    ``info["reward_terms"]``:

    - ``progress``: ``progress_reward_per_m`` times the decrease of the geodesic distance to
      the goal (shortest route over the navigation graph, straight where the goal or a node
      is in sight; see :mod:`sim.envs.geometry`), on the true pose;
    - ``success``: ``success_reward`` once, when the true position comes within
      ``goal_radius_m`` of the goal;
    - ``collision``: ``collision_reward`` per new contact episode (the robot starting to touch
      a wall, furniture or a person, counted as :meth:`sim.simulator.world.World.step_frame` does);
    - ``time``: ``time_reward`` every step.

    ## Episode end

    Terminated on success (``terminate_on_success``) or on a collision
    (``terminate_on_collision``); truncated after ``max_steps`` steps.

    ## Info

    ``pose`` (true x, y, theta), ``pose_estimate``, ``loc_error_m``, ``loc_resets``,
    ``goal`` (world x, y), ``goal_distance_m`` (geodesic), ``collisions`` (this episode),
    ``collided`` (this step), ``success`` and its alias ``is_success``, ``steps``, and after
    a step ``reward_terms``.

    ## Randomness

    Every draw (building, furniture, people, start and goal, odometry noise, Kinect noise
    seeds, FSPF seeds, CGR) comes from ``self.np_random``: ``reset(seed=s)`` then the same
    actions give the same observations, bit for bit. A seeded reset also restarts the
    procedural building schedule.

    ## Rendering

    ``render_mode="rgb_array"``: a ``render_size`` (480 x 640) top-down view of the building
    with the walls, navigation graph, furniture, people, the planned route, the goal, the
    camera's field of view, the CGR particles and estimate, and the robot.
    ``render_mode="depth"``: the last depth observation, Turbo-coloured (invalid black),
    upscaled to at least 240 rows. The renderers (and the GL context) are made lazily, so
    the env works in ``gymnasium.vector.AsyncVectorEnv`` workers.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 30}

    def __init__(
        self,
        config: EnvConfig | None = None,
        *,
        scenario: str | Path | None = None,
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        if config is not None and scenario is not None:
            raise InputError("DepthNav: give 'config' or 'scenario', not both")
        if config is not None and not isinstance(config, EnvConfig):
            raise InputError(f"DepthNav: argument 'config' expected an EnvConfig, got {type(config).__name__}")
        if scenario is not None:
            cfg = EnvConfig.from_scenario(scenario, **overrides)
        else:
            cfg = (config or EnvConfig()).replace(**overrides) if overrides else (config or EnvConfig())
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise InputError(f"DepthNav: argument 'render_mode' expected None or one of {', '.join(RENDER_MODES)}, got {render_mode!r}")
        self.config = cfg
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": int(round(cfg.kinect.rate_hz))}

        h, w = cfg.depth_shape
        self.intrinsics: CameraIntrinsics = cfg.kinect.intrinsics.scaled(w, h)
        self._kinect = replace(cfg.kinect, intrinsics=self.intrinsics, noise=replace(cfg.kinect.noise, threads=1))
        self._fspf_cfg = replace(cfg.fspf, eta_px=max(2, round(cfg.fspf.eta_px * w / cfg.kinect.intrinsics.width)))
        self.frame_dt = 1.0 / cfg.kinect.rate_hz
        self.n_substeps = max(1, round(self.frame_dt / cfg.world.timestep_s))
        max_range = cfg.kinect.noise.max_range_m
        self.depth_max_m = float(max_range) if math.isfinite(max_range) else FAR_PLANE_M
        self._need_fspf = cfg.localization.enabled or cfg.observe_points > 0
        self._scanner = (
            KCScanner(self.intrinsics, cfg.kinect.mount, cfg.observe_scan, cfg.scan_min_height_m, cfg.scan_max_height_m, self.depth_max_m)
            if cfg.observe_scan
            else None
        )
        self._fixed = _load_building(cfg)

        self.action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        obs: dict[str, spaces.Space] = {
            "depth": spaces.Box(0.0, self.depth_max_m, (h, w), np.float32),
            "goal": spaces.Box(-GOAL_LIMIT_M, GOAL_LIMIT_M, (2,), np.float32),
            "odometry": spaces.Box(
                np.array([-1.0, -1.0, -np.pi], np.float32), np.array([1.0, 1.0, np.pi], np.float32), dtype=np.float32
            ),
        }
        if cfg.observe_points:
            rays = np.hypot(1.0, np.hypot(*(np.array([w, h]) / 2 / np.array([self.intrinsics.fx, self.intrinsics.fy]))))
            b = float(self.depth_max_m * rays + np.linalg.norm(cfg.kinect.mount.translation()) + 0.01)
            lo = np.array([-b, -b, -b, -1, -1, -1, 0, 0], np.float32)
            hi = np.array([b, b, b, 1, 1, 1, 1, 1], np.float32)
            self._points_low = np.broadcast_to(lo, (cfg.observe_points, 8)).copy()
            self._points_high = np.broadcast_to(hi, (cfg.observe_points, 8)).copy()
            obs["points"] = spaces.Box(self._points_low, self._points_high, dtype=np.float32)
        if cfg.observe_scan:
            obs["scan"] = spaces.Box(0.0, np.float32(self._scanner.max_range_m), (cfg.observe_scan,), np.float32)
        if cfg.observe_pose_estimate:
            L = POSITION_LIMIT_M
            obs["pose_estimate"] = spaces.Box(
                np.array([-L, -L, -np.pi, 0.0, 0.0], np.float32), np.array([L, L, np.pi, L, 10.0], np.float32), dtype=np.float32
            )
        self.observation_space = spaces.Dict(obs)

        # Episode state (made in reset; nothing unpicklable is created here).
        self._site: _Site | None = None
        self._episodes_on_site = 0
        self._ready = False
        self._recorder = None
        self._rrd_frame = 0
        self._rrd_time = 0.0
        self._rrd_site: _Site | None = None

    # -- buildings ------------------------------------------------------------------
    def _make_site(self, building: Building, seed: int | None) -> _Site:
        cfg = self.config
        # Kinds from the building's own seed, not np_random: a fixed building is compiled
        # at the first reset only, and every reset must draw the same from np_random.
        rng = np.random.default_rng(0 if seed is None else seed)
        kinds = ("table", "chair", "box", "cabinet")
        furniture = list(cfg.furniture) + [
            Furniture(kind=str(kinds[rng.integers(len(kinds))]), x=_PARK_XY[0] - 10.0 * i, y=_PARK_XY[1]) for i in range(cfg.n_furniture)
        ]
        park = (_PARK_XY, (_PARK_XY[0] + 1.0, _PARK_XY[1]))
        people = list(cfg.people) + [Person(route=park, speed_mps=0.0) for _ in range(cfg.n_people)]
        world = build_world(
            building.vectormap,
            world=cfg.world,
            robot=cfg.robot,
            intrinsics=self.intrinsics,
            mount=cfg.kinect.mount,
            furniture=tuple(furniture),
            people=tuple(people),
        )
        bodies = np.array(
            [mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_BODY, f"furniture_{i}") for i in range(len(furniture))], dtype=np.int64
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
        return _Site(
            building=building,
            world=world,
            camera=KinectCamera(world.model, world.camera_id, self._kinect),
            adj=adjacency(building.navgraph),
            walls=np.ascontiguousarray(building.vectormap.segments, dtype=np.float64).reshape(-1, 4),
            edges=building.navgraph.edge_segments(),
            furniture=furniture,
            furniture_bodies=bodies,
            mocap_ids=world.people.mocap_ids.copy(),
            query=query,
            seed=seed,
        )

    def _ensure_site(self, seeded: bool) -> None:
        cfg = self.config
        if self._fixed is not None:
            if self._site is None:
                self._site = self._make_site(self._fixed, None)
            return
        # Procedural, drawn from np_random: a seeded reset always draws a new building.
        if self._site is None or seeded or self._episodes_on_site >= cfg.new_building_every:
            seed = int(self.np_random.integers(0, 2**31 - 1))
            if self._site is not None and self._site.seed == seed:
                self._episodes_on_site = 0
                return
            b = _procedural(cfg, seed)
            _check_building(cfg, b)
            if self._site is not None:
                self._site.camera.close()
            self._site = self._make_site(b, seed)
            self._episodes_on_site = 0

    def _place_furniture(self, site: _Site, rng: np.random.Generator) -> None:
        """Re-place the random pieces (same constraints as sim.experiments.runner.random_furniture)."""
        cfg = self.config
        b = site.building
        zones = b.open_areas or b.rooms
        radius = cfg.robot.radius_m
        placed: list[Furniture] = list(site.furniture[: len(cfg.furniture)])
        model = site.world.model
        for k in range(len(cfg.furniture), len(site.furniture)):
            base = site.furniture[k]
            half_diag = 0.5 * math.hypot(base.dims[0], base.dims[1])
            new = replace(base, x=_PARK_XY[0] - 10.0 * k, y=_PARK_XY[1])
            for _ in range(500):
                z = zones[int(rng.integers(len(zones)))]
                f = replace(base, x=float(rng.uniform(z[0], z[2])), y=float(rng.uniform(z[1], z[3])), yaw=float(rng.uniform(-math.pi, math.pi)))
                p = np.array([f.x, f.y])
                if len(site.edges) and point_segment_distance(p, site.edges).min() < half_diag + radius + 0.15:
                    continue
                if len(site.walls) and point_segment_distance(p, site.walls).min() < half_diag + 0.05:
                    continue
                if any(math.hypot(o.x - f.x, o.y - f.y) < half_diag + 0.5 * math.hypot(*o.dims[:2]) + 0.1 for o in placed):
                    continue
                new = f
                break
            placed.append(new)
            bid = site.furniture_bodies[k]
            model.body_pos[bid] = [new.x, new.y, 0.0]
            model.body_quat[bid] = _yaw_quat(new.yaw)
            site.furniture[k] = new

    def _route_people(self, site: _Site, rng: np.random.Generator) -> None:
        cfg = self.config
        routes = list(random_people(site.building.navgraph, cfg.n_people, rng)) if cfg.n_people else []
        park = (_PARK_XY, (_PARK_XY[0] + 1.0, _PARK_XY[1]))
        routes += [Person(route=park, speed_mps=0.0) for _ in range(cfg.n_people - len(routes))]
        self._people = list(cfg.people) + routes
        site.world.people = PeopleController(tuple(self._people), site.mocap_ids, site.walls, robot_radius_m=self.config.robot.radius_m)

    def _clear_start(self, site: _Site, start_xy: np.ndarray, rng: np.random.Generator) -> None:
        """Move random people's start offsets until none touches the robot's start."""
        cfg = self.config
        first = len(cfg.people)
        for _ in range(20):
            pos = site.world.people.positions()
            bad = [
                i
                for i in range(first, len(self._people))
                if math.hypot(*(pos[i, :2] - start_xy)) < cfg.robot.radius_m + self._people[i].radius_m + 0.5
            ]
            if not bad:
                return
            for i in bad:
                self._people[i] = replace(self._people[i], start_offset_m=float(rng.uniform(0.0, 40.0)))
            site.world.people = PeopleController(tuple(self._people), site.mocap_ids, site.walls, robot_radius_m=self.config.robot.radius_m)

    def _sample_task(self, site: _Site, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        cfg = self.config
        g = site.building.navgraph
        ids = [int(i) for i in g.node_ids()]
        xy = g.node_xy()
        starts = list(cfg.start_nodes) or ids
        goals = list(cfg.goal_nodes) or ids
        hi = cfg.max_goal_distance_m or math.inf
        choice = None
        fallback = None
        for _ in range(30):
            s = starts[int(rng.integers(len(starts)))]
            d = _dijkstra(site.adj, g.index_of(s))
            dg = np.array([d[g.index_of(t)] if t != s else np.inf for t in goals])
            ok = np.flatnonzero((dg >= cfg.min_goal_distance_m) & (dg <= hi))
            if len(ok):
                choice = (s, goals[int(ok[rng.integers(len(ok))])])
                break
            finite = np.flatnonzero(np.isfinite(dg))
            if len(finite) and fallback is None:
                fallback = (s, goals[int(finite[np.argmax(dg[finite])])])
        choice = choice or fallback
        if choice is None:
            raise InputError("DepthNav: no goal node is reachable from the start nodes in the navigation graph")
        s, t = choice
        p = xy[g.index_of(s)]
        start = np.array([p[0], p[1], rng.uniform(-math.pi, math.pi)])
        return start, xy[g.index_of(t)].astype(np.float64).copy()

    # -- gymnasium API ----------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode. ``options``: ``start_pose`` (x, y, theta) and/or ``goal`` (x, y)."""
        super().reset(seed=seed)
        opts = dict(options or {})
        unknown = set(opts) - {"start_pose", "goal"}
        if unknown:
            raise InputError(f"DepthNav: reset option {sorted(unknown)[0]!r} unknown (expected start_pose, goal)")
        start_opt = _option_array(opts, "start_pose", 3)
        goal_opt = _option_array(opts, "goal", 2)
        rng = self.np_random
        self._ensure_site(seeded=seed is not None)
        site = self._site
        assert site is not None
        self._episodes_on_site += 1
        if self.config.n_furniture:
            self._place_furniture(site, rng)
        self._route_people(site, rng)
        start, goal = self._sample_task(site, rng)
        if start_opt is not None:
            start = start_opt
        if goal_opt is not None:
            goal = goal_opt
        start[2] = math.atan2(math.sin(start[2]), math.cos(start[2]))
        self._clear_start(site, start[:2], rng)
        site.world.reset(tuple(start))
        self.goal = goal
        self._field = GeodesicField(site.building.navgraph, site.walls, goal, self.config.geodesic_radius_m)
        self._odom = Odometry(self.config.odometry, rng, start)
        self._localizer = None
        if self.config.localization.enabled:
            q = site.query
            assert q is not None
            self._localizer = CGRLocalizer(
                lambda x, y: q.scene_lines(x, y)[0], self.config.localization.cgr, self.config.localization.observation, rng
            )
            self._localizer.reset(start)
        self._estimate = start.copy()
        self._increment = np.zeros(3)
        self._pose = start.copy()
        self._steps = 0
        self._collisions = 0
        self._loc_resets = 0
        self._success = False
        self._collided = False
        self._ready = True
        self._sense()
        self._phi, _ = self._field.distance(self._pose[:2])
        if cfg_rrd := self.config.rrd:
            self._log_rrd(cfg_rrd, new_episode=True)
        return self._observation(), self._info(None)

    def step(self, action):
        if not self._ready:
            raise gym.error.ResetNeeded("DepthNav: call reset() before step()")
        cfg = self.config
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (3,):
            raise InputError(f"DepthNav: action expected shape (3,) (vx, vy, omega in [-1, 1]), got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise InputError(f"DepthNav: action expected finite numbers, got {a!r}")
        a = np.clip(a, -1.0, 1.0)
        site = self._site
        assert site is not None
        world = site.world
        v = np.array([a[0] * cfg.robot.max_speed_mps, a[1] * cfg.robot.max_speed_mps, a[2] * cfg.robot.max_angular_rad_s])
        world.robot.command(world.data, v, self.frame_dt)
        world.people.update(world.data, world.data.time + self.frame_dt, self._pose[:2])
        events = world.step_frame(self.n_substeps)
        self._steps += 1
        self._collisions += events
        self._collided = events > 0
        self._sense()
        if cfg.rrd:
            self._log_rrd(cfg.rrd, new_episode=False)

        phi, _ = self._field.distance(self._pose[:2])
        reached = math.hypot(*(self._pose[:2] - self.goal)) <= cfg.goal_radius_m
        first_success = reached and not self._success
        self._success = self._success or reached
        terms = {
            "progress": cfg.progress_reward_per_m * (self._phi - phi),
            "success": cfg.success_reward if first_success else 0.0,
            "collision": cfg.collision_reward * events,
            "time": cfg.time_reward,
        }
        self._phi = phi
        reward = float(terms["progress"] + terms["success"] + terms["collision"] + terms["time"])
        terminated = bool((cfg.terminate_on_success and reached) or (cfg.terminate_on_collision and events > 0))
        truncated = bool(self._steps >= cfg.max_steps and not terminated)
        return self._observation(), reward, terminated, truncated, self._info(terms)

    # -- sensing ----------------------------------------------------------------------
    def _sense(self) -> None:
        """Render the frame at the current state; odometry, FSPF and localization on it."""
        site = self._site
        assert site is not None
        world = site.world
        rng = self.np_random
        cfg = self.config
        if _GL_INHERITED and site.camera._backend is None and cfg.kinect.backend != "raycast":
            raise RuntimeError(
                "DepthNav: this process was forked from one that had already rendered with EGL, "
                "and OpenGL cannot render after fork(); make AsyncVectorEnv(..., context='spawn') "
                "(or 'forkserver'), or create the vector env before rendering in the parent"
            )
        depth = site.camera.capture(world.data, int(rng.integers(0, 2**63)))
        if not math.isfinite(cfg.kinect.noise.max_range_m):
            depth = np.where(depth <= self.depth_max_m, depth, np.float32(0.0))
        self._depth = depth.copy()
        new_pose = world.robot.pose(world.data)
        if self._steps > 0:
            self._increment = self._odom.update(new_pose)
        self._pose = new_pose
        self._planes: FSPFResult | None = None
        if self._need_fspf:
            self._planes = fspf(self._depth, self.intrinsics, self._fspf_cfg, seed=int(rng.integers(0, 2**63)), mount=cfg.kinect.mount)
        loc = self._localizer
        if loc is not None:
            if self._steps > 0:
                loc.predict(self._increment)
                p2, n2 = self._planes.projected(self._fspf_cfg.max_vertical_normal_angle_rad)
                loc.update(p2, n2)
            est = loc.estimate()
            self._estimate = est.pose.copy()
            self._spread = (est.std_xy_m, est.std_theta_rad)
            if math.hypot(*(self._estimate[:2] - new_pose[:2])) > cfg.localization.reset_error_m:
                self._loc_resets += 1
                loc.reset(new_pose)
                est = loc.estimate()
                self._estimate = est.pose.copy()
                self._spread = (est.std_xy_m, est.std_theta_rad)
        else:
            self._estimate = self._odom.pose.copy()
            self._spread = (0.0, 0.0)

    def _observation(self) -> dict[str, np.ndarray]:
        cfg = self.config
        ref = self._pose if cfg.goal_from_truth else self._estimate
        rel = relative_pose(ref, np.array([self.goal[0], self.goal[1], 0.0]))[:2]
        inc = self._increment
        obs = {
            "depth": self._depth.copy(),
            "goal": np.clip(rel.astype(np.float32), -GOAL_LIMIT_M, GOAL_LIMIT_M),
            "odometry": np.clip(
                inc.astype(np.float32), np.array([-1, -1, -np.pi], np.float32), np.array([1, 1, np.pi], np.float32)
            ),
        }
        if cfg.observe_points:
            obs["points"] = self._points_obs()
        if cfg.observe_scan:
            assert self._scanner is not None
            obs["scan"] = self._scanner.scan(self._depth)
        if cfg.observe_pose_estimate:
            e = self._estimate
            L = POSITION_LIMIT_M
            pe = np.array([e[0], e[1], e[2], self._spread[0], self._spread[1]], dtype=np.float32)
            obs["pose_estimate"] = np.clip(
                pe, np.array([-L, -L, -np.pi, 0, 0], np.float32), np.array([L, L, np.pi, L, 10.0], np.float32)
            )
        return obs

    def _points_obs(self) -> np.ndarray:
        n_cap = self.config.observe_points
        out = np.zeros((n_cap, 8), dtype=np.float32)
        pl = self._planes
        if pl is None:
            return out
        n_p, n_o = len(pl.points), len(pl.outliers)
        total = n_p + n_o
        if total == 0:
            return out
        idx = np.arange(total)
        if total > n_cap:
            idx = np.sort(self.np_random.choice(total, n_cap, replace=False))
        k = len(idx)
        is_p = idx < n_p
        ip, io = idx[is_p], idx[~is_p] - n_p
        m = len(ip)
        out[:m, :3] = pl.points[ip]
        out[:m, 3:6] = pl.normals[ip]
        out[:m, 6] = 1.0
        out[m:k, :3] = pl.outliers[io]
        out[:k, 7] = 1.0
        np.clip(out, self._points_low, self._points_high, out=out)
        return out

    def _info(self, terms: dict[str, float] | None) -> dict[str, Any]:
        info: dict[str, Any] = {
            "pose": self._pose.copy(),
            "pose_estimate": self._estimate.copy(),
            "loc_error_m": float(math.hypot(*(self._estimate[:2] - self._pose[:2]))),
            "loc_resets": self._loc_resets,
            "goal": self.goal.copy(),
            "goal_distance_m": float(self._phi),
            "collisions": self._collisions,
            "collided": self._collided,
            "success": self._success,
            "is_success": self._success,
            "steps": self._steps,
        }
        if terms is not None:
            info["reward_terms"] = {k: float(terms[k]) for k in REWARD_TERMS}
        return info

    # -- rendering --------------------------------------------------------------------
    def render(self):
        if self.render_mode is None:
            gym.logger.warn("DepthNav: render() without a render_mode; pass render_mode='rgb_array' or 'depth'")
            return None
        if not self._ready:
            raise gym.error.ResetNeeded("DepthNav: call reset() before render()")
        if self.render_mode == "depth":
            h = self._depth.shape[0]
            return depth_to_rgb(self._depth, self.depth_max_m, upscale=max(1, math.ceil(240 / h)))
        return self._render_map()

    def _render_map(self) -> np.ndarray:
        site = self._site
        assert site is not None
        cfg = self.config
        if site.canvas is None:
            site.canvas = MapCanvas(site.building.vectormap, site.building.navgraph, cfg.render_size)
        cv = site.canvas
        img = cv.background.copy()
        s = cv.scale
        pose = self._pose
        # The camera's horizontal field of view out to the maximum range.
        cam = cfg.kinect.mount.translation()
        c, sn = math.cos(pose[2]), math.sin(pose[2])
        cxy = pose[:2] + np.array([c * cam[0] - sn * cam[1], sn * cam[0] + c * cam[1]])
        half = self.intrinsics.fov_h_rad / 2
        r = min(self.depth_max_m, 6.0)
        ends = np.array([cxy + r * np.array([math.cos(pose[2] + a), math.sin(pose[2] + a)]) for a in (-half, half)])
        draw_segments(img, cv.px(np.vstack([cxy, cxy])), cv.px(ends), FRUSTUM)
        for f in site.furniture:
            lx, ly, _ = f.dims
            cf, sf = math.cos(f.yaw), math.sin(f.yaw)
            corners = np.array([[sx * lx / 2, sy * ly / 2] for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
            world_c = np.column_stack([f.x + cf * corners[:, 0] - sf * corners[:, 1], f.y + sf * corners[:, 0] + cf * corners[:, 1]])
            fill_convex(img, cv.px(world_c), FURNITURE)
        people = site.world.people.positions()
        for i, p in enumerate(self._people):
            u, v = cv.px(people[i, :2])[0]
            draw_disk(img, u, v, max(2.0, p.radius_m * s), PERSON)
        path = self._field.path(pose[:2])
        draw_segments(img, cv.px(path[:-1]), cv.px(path[1:]), PATH, thickness=2)
        gu, gv = cv.px(self.goal)[0]
        draw_disk(img, gu, gv, max(3.0, 0.15 * s), GOAL)
        draw_disk(img, gu, gv, max(4.0, cfg.goal_radius_m * s), GOAL, ring=True)
        if self._localizer is not None:
            draw_points(img, cv.px(self._localizer.particles[:, :2]), PARTICLE)
        e = self._estimate
        eu, ev = cv.px(e[:2])[0]
        draw_disk(img, eu, ev, max(2.0, 0.1 * s), ESTIMATE)
        ru, rv = cv.px(pose[:2])[0]
        rr = max(3.0, cfg.robot.radius_m * s)
        draw_disk(img, ru, rv, rr, ROBOT, ring=True)
        head = cv.px(pose[:2] + cfg.robot.radius_m * 1.6 * np.array([c, sn]))
        draw_segments(img, np.array([[ru, rv]]), head, ROBOT, thickness=2)
        return img

    def _log_rrd(self, path: str, new_episode: bool) -> None:
        """Stream this step to the rerun recording (sim.viz.recording.Recorder), made on first use."""
        from sim.viz.recording import Recorder

        site = self._site
        assert site is not None
        if self._recorder is None:
            self._recorder = Recorder(path, every=self.config.rrd_every, depth_downsample=1, application_id="depthnav-env")
            self._recorder.log_camera_model(self.intrinsics, self.config.kinect.mount)
            self._recorder.log_robot_shape(self.config.robot.radius_m, self.config.robot.height_m)
        rec = self._recorder
        if site is not self._rrd_site:
            rec.log_map(site.building.vectormap, site.building.navgraph, self.config.world.wall_height_m)
            self._rrd_site = site
        if new_episode:
            rec.set_time(self._rrd_frame, self._rrd_time)
            rec.log_waypoints(np.asarray(self.goal, dtype=np.float64).reshape(1, 2), static=False)
            rec.reset_trajectory()
        self._rrd_frame += 1
        self._rrd_time += self.frame_dt
        rec.set_time(self._rrd_frame, self._rrd_time)
        rec.log_pose(self._rrd_frame, self._pose)
        if self._localizer is not None:
            rec.log_estimate(self._rrd_frame, self._estimate)
        if rec.heavy(self._rrd_frame):
            rec.log_depth(self._depth)
            if self._planes is not None:
                rec.log_fspf(self._planes)
            if self._localizer is not None:
                rec.log_localization(self._localizer.before_refinement, self._localizer.after_refinement, self._localizer.refined_weights)
            rec.log_people(site.world.people.positions())
            rec.log_scalars({"env/steps": float(self._steps), "env/collisions": float(self._collisions)})

    def close(self) -> None:
        if self._recorder is not None:
            self._recorder.close()
            self._recorder = None
        if self._site is not None:
            self._site.camera.close()
            self._site = None
        self._ready = False
        super().close()


def _option_array(opts: dict[str, Any], key: str, n: int) -> np.ndarray | None:
    if key not in opts or opts[key] is None:
        return None
    try:
        a = np.asarray(opts[key], dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise InputError(f"DepthNav: reset option '{key}' expected {n} finite numbers, got {opts[key]!r}")
    return a.copy()

