"""Configuration of the ``DepthNav-v0`` environment: one frozen dataclass, checked strictly.

Every field has a one-line doc; ``gymnasium.make("DepthNav-v0", **fields)`` and
:meth:`EnvConfig.from_scenario` both go through the same type and range checks, so a
mistake is a one-line :class:`autonomy.common.errors.InputError` naming the argument.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from autonomy.navigation.avoidance import AvoidanceConfig
from autonomy.navigation.config import NavigatorConfig
from autonomy.perception.fspf import FSPFConfig
from autonomy.stack import StackConfig
from sim.scenario import LocalizationConfig, load_scenario, robot_localization
from sim.simulator import blueprints
from sim.simulator.actors import Furniture, Person
from sim.simulator.kinect import KinectConfig
from sim.simulator.robot import OdometryConfig, RobotConfig, avoidance_for_body
from sim.simulator.world import WorldConfig


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
    or '' when ``vectormap`` is given."""
    vectormap: str = ""
    """A vector-map file (text or JSON), with ``building=''``; random furniture goes
    anywhere in its free space."""
    navgraph: str = ""
    """The navigation-graph file that goes with ``vectormap``; empty: a graph made from
    the walls for ``robot.radius_m``, cached as <vectormap>.auto.navigation.json."""
    procedural: blueprints.BuildingConfig = field(default_factory=_default_procedural)
    """Generator parameters for ``building='procedural'`` (default: 30 x 24 m floors)."""
    building_seed: int = -1
    """procedural: >= 0 fixes the building (a scenario's map.generate_seed); -1 draws
    buildings from np_random."""
    new_building_every: int = 1
    """procedural with building_seed -1: draw a new building every N episodes (a reset
    with a seed always draws one)."""
    building_seeds: tuple[int, ...] = ()
    """procedural: draw each new building's seed from these with np_random (a fixed set of
    buildings, e.g. a training split, sim.rl.splits) instead of any seed; empty: any."""
    # -- actors ---------------------------------------------------------------------
    furniture: tuple[Furniture, ...] = ()
    """Fixed furniture pieces (unmapped clutter)."""
    people: tuple[Person, ...] = ()
    """People walking fixed routes."""
    n_furniture: int = 0
    """Extra furniture pieces (kinds drawn per building) placed at random in the open
    areas (or rooms; a map without zones: its free space), clear of the navigation graph,
    every episode."""
    n_people: int = 0
    """Extra people walking random navigation-graph routes, redrawn every episode."""
    # -- episodes -------------------------------------------------------------------
    start_nodes: tuple[int, ...] = ()
    """Navigation-graph node ids to start at (empty: any node of the graph's largest
    connected component)."""
    goal_nodes: tuple[int, ...] = ()
    """Node ids to draw goals from (empty: any node of the largest connected component)."""
    min_goal_distance_m: float = 2.0
    """Smallest geodesic start-goal distance drawn."""
    max_goal_distance_m: float = 0.0
    """Largest geodesic start-goal distance drawn (0: no limit)."""
    goal_radius_m: float = 0.5
    """Success when the true position is this close to the goal."""
    max_steps: int = 1000
    """Truncate an episode after this many steps (1000 frames = 33 s at 30 Hz)."""
    frames_per_step: int = 1
    """Camera frames per env step: the policy decides at ``kinect.rate_hz`` / this (6: at
    5 Hz), the command held between decisions; the physics and the people keep the
    camera's rate, and the robot senses once per step, on the last frame (one render,
    Kinect noise, FSPF and CGR update, on the odometry of all the step's frames)."""
    rrd: str = ""
    """Write a rerun recording of every step to this .rrd file (made lazily in the process
    that steps the env; in a vector env give each env its own file)."""
    rrd_every: int = 5
    """Log the heavy items (depth, FSPF points, particles) every Nth step."""
    terminate_on_success: bool = True
    """End the episode (terminated) on reaching the goal."""
    terminate_on_collision: bool = True
    """End the episode (terminated) on a collision."""
    safety_layer: bool = False
    """Pass the action through the robot's safety layer
    (:func:`autonomy.navigation.safety.safe_command`): the velocity nearest to it from
    which the robot stops short of everything the robot stack knows of round it (the
    ``ranges`` observation's source) while the command is held for a decision, as a
    learned local planner drives through a real robot's safety controller. Needs a task
    that observes ``ranges``."""
    # -- rewards --------------------------------------------------------------------
    progress_reward_per_m: float = 1.0
    """Reward per metre of geodesic progress towards the goal (negative when receding)."""
    success_reward: float = 10.0
    """Reward on reaching the goal (once per episode)."""
    collision_reward: float = -10.0
    """Reward per new collision (a contact episode starting)."""
    collision_debounce_s: float = 0.0
    """A contact starting within this many seconds of the last penalised one is counted
    in ``collisions`` but not penalised again (a robot pinned on a wall touches and lets
    go over and over); 0: every one is."""
    collision_penalties: int = 0
    """At most this many collisions penalised per episode (0: no limit), so one bad
    episode's return stays bounded."""
    time_reward: float = -0.01
    """Reward every step."""
    clearance_reward: float = 0.0
    """Reward every step, times how far inside ``clearance_m`` of the robot's surface the
    nearest thing the robot stack knows of is (0 outside it, 1 touching; the stack's
    ``known`` points, the ``ranges`` observation's source): a negative weight teaches
    keeping off walls before touching them (0: no such term; needs a task that observes
    ``ranges``)."""
    clearance_m: float = 0.3
    """... the margin it counts from."""
    # -- observations ---------------------------------------------------------------
    depth_shape: tuple[int, int] = (120, 160)
    """(rows, columns) of the depth observation; same aspect ratio as kinect.intrinsics.
    The camera renders at this size directly (scaled intrinsics, same field of view)."""
    depth_layout: str = "hwc"
    """Axes of the depth observation: 'hwc' (rows, columns, 1: an image with a channel
    axis, as gymnasium's image wrappers and stable-baselines3's CnnPolicy take it), 'chw'
    (1, rows, columns: PyTorch's order) or 'hw' (rows, columns)."""
    depth_dtype: str = "float32"
    """'float32': metres, 0 = invalid (with stable-baselines3, pass
    ``policy_kwargs=dict(normalize_images=False)``); 'uint8': depth scaled to 1-255 over
    (0, depth range], 0 = invalid, the image type CNN policies normalise by 255 themselves."""
    goal_format: str = "cartesian"
    """'cartesian': the goal's (x, y) in the robot frame, metres; 'polar': (distance in
    metres, bearing in radians counter-clockwise from the robot's heading), Habitat's
    PointGoal convention; 'unit': (distance / ``goal_scale_m`` capped at 1, cosine and
    sine of the bearing), every term in [-1, 1]."""
    goal_scale_m: float = 10.0
    """The distance that 'unit' goals scale to 1."""
    goal_from_truth: bool = False
    """Observe the goal relative to the true pose instead of the pose estimate."""
    observe_points: int = 0
    """> 0: add ``points``, this many FSPF points (padded, with a mask column)."""
    observe_scan: int = 0
    """> 0: add ``scan``, a KC-style laser scan with this many bins over the camera's
    horizontal field of view. More bins than depth columns leave empty bins (the paper's
    0.35 degrees is 165 bins, which needs depth_shape (480, 640))."""
    observe_depth: bool = True
    """Add ``depth`` (the decision-level tasks leave it out: their ``ranges`` hold what
    the robot knows round it, which a small policy learns from faster)."""
    observe_ranges: int = 0
    """> 0: add ``ranges``, the nearest obstacle in this many bearing bins all round the
    robot as the robot stack knows them: the map's walls through the pose estimate, the
    obstacle memory (what the camera saw, kept where it no longer looks) and the near
    field (closer than the camera's minimum range), each range divided by
    ``ranges_max_m`` (1: nothing within it)."""
    ranges_max_m: float = 4.0
    """The reach of ``ranges`` (the Kinect's 4 m)."""
    observe_plan: int = 0
    """> 0: add ``plan``, this many points of the robot stack's plan on the navigation
    graph ahead of the pose estimate, ``plan_spacing_m`` apart along it, in the robot
    frame, divided by ``ranges_max_m`` (the route a global planner gives a learned local
    planner)."""
    plan_spacing_m: float = 1.0
    """Metres along the plan between the ``plan`` points."""
    observe_velocity: bool = False
    """Add ``velocity``: the base's body-frame velocity now (vx, vy, omega as fractions of
    the limits the action scales to; the acceleration limits make it lag the action)."""
    history: int = 1
    """Decisions of ``ranges`` stacked (the newest first), the policy's short memory."""
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
    ``calibrated_motion``: CGR's motion noise the odometry's, as in a scenario run.
    Above ``reset_error_m`` error the filter is re-initialised at the true pose at once
    (episodes are short; scenario runs wait ``truth_reset_after_s`` for the robot's own
    recovery) and ``info['loc_resets']`` counts it."""
    avoidance: AvoidanceConfig = field(default_factory=AvoidanceConfig)
    """The robot stack's obstacle avoidance (its robot radius is ``robot.radius_m``)."""
    navigator: NavigatorConfig = field(default_factory=lambda: NavigatorConfig(shortcut_clearance_m=0.0))
    """The robot stack's navigator (``stack_policy``; its plan is the ``plan`` observation).
    The registered tasks' episodes and scores were measured on the graph's own paths, so
    by default its plans are not straightened (``shortcut_clearance_m`` 0): straightened
    plans change the ``plan`` observation and the classical baseline, a new version."""
    stack_policy: bool = False
    """Run the robot stack's navigator every step towards the goal (on the pose estimate)
    and put its command in ``info['stack_command']`` (m/s, m/s, rad/s) and, scaled as an
    action, ``info['stack_action']``: the classical stack as an expert or a baseline."""

    def __post_init__(self) -> None:
        _check_types(self)
        # The stack avoids with the body the simulator drives: one radius, robot.radius_m.
        object.__setattr__(self, "avoidance", avoidance_for_body(self.avoidance, self.robot, "DepthNav"))

        def need(ok: bool, name: str, what: str) -> None:
            if not ok:
                raise InputError(f"DepthNav: argument '{name}' expected {what}, got {getattr(self, name)!r}")

        choices = sum([bool(self.building), bool(self.vectormap)])
        if choices != 1 or (self.navgraph and not self.vectormap):
            raise InputError(
                "DepthNav: give exactly one of 'building' (a shipped name, a blueprint stem or "
                "'procedural') or 'vectormap', optionally with 'navgraph' (and building='')"
            )
        need(self.new_building_every >= 1, "new_building_every", "an integer >= 1")
        need(self.building_seed >= -1, "building_seed", "an integer >= -1")
        if self.building_seeds:
            need(self.building == "procedural", "building_seeds", "() unless building='procedural'")
            need(min(self.building_seeds) >= 0, "building_seeds", "seeds >= 0")
            need(self.building_seed < 0, "building_seeds", "() when building_seed >= 0 fixes the building")
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
        need(self.depth_layout in ("hwc", "chw", "hw"), "depth_layout", "'hwc', 'chw' or 'hw'")
        need(self.depth_dtype in ("float32", "uint8"), "depth_dtype", "'float32' or 'uint8'")
        need(self.goal_format in ("cartesian", "polar", "unit"), "goal_format", "'cartesian', 'polar' or 'unit'")
        need(self.goal_scale_m > 0, "goal_scale_m", "a positive number")
        need(self.frames_per_step >= 1, "frames_per_step", "an integer >= 1")
        need(self.collision_debounce_s >= 0, "collision_debounce_s", "a number >= 0")
        need(self.collision_penalties >= 0, "collision_penalties", "an integer >= 0 (0: no limit)")
        need(self.clearance_m > 0, "clearance_m", "a positive number of metres")
        need(self.clearance_reward == 0 or self.observe_ranges > 0, "clearance_reward",
             "0 unless observe_ranges > 0 (the term reads what the robot stack knows round the robot)")
        need(not self.safety_layer or self.observe_ranges > 0, "safety_layer",
             "False unless observe_ranges > 0 (it brakes before what 'ranges' reads)")
        need(self.observe_ranges >= 0, "observe_ranges", "an integer >= 0 (0: no 'ranges' key)")
        need(self.ranges_max_m > 0, "ranges_max_m", "a positive number")
        need(self.observe_plan >= 0, "observe_plan", "an integer >= 0 (0: no 'plan' key)")
        need(self.plan_spacing_m > 0, "plan_spacing_m", "a positive number")
        need(self.history >= 1, "history", "an integer >= 1")
        need(
            not (self.observe_ranges or self.observe_plan) or self.localization.enabled,
            "observe_ranges" if self.observe_ranges else "observe_plan",
            "0 when localization.enabled is False (the robot stack places them through its estimate)",
        )
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

    def stack_config(self, kinect: KinectConfig, fspf: FSPFConfig) -> StackConfig:
        """The robot stack's configuration for the camera at the observation's size."""
        navigate = self.stack_policy or self.observe_ranges > 0 or self.observe_plan > 0
        loc = robot_localization(self.localization, self.odometry)
        return StackConfig(kinect.depth_camera(), fspf, loc, self.avoidance, self.navigator, navigate=navigate)

    @property
    def action_scale(self) -> np.ndarray:
        """What an action of 1 means (vx, vy in m/s, omega in rad/s): the robot's limits."""
        return np.array([self.robot.max_speed_mps, self.robot.max_speed_mps, self.robot.max_angular_rad_s])

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
            where = dict(building="procedural", building_seed=m.generate_seed, procedural=m.building_config())
        elif m.name:
            where = dict(building=m.name)
        else:
            where = dict(building="", vectormap=str(scn.resolve(m.vectormap)), navgraph=str(scn.resolve(m.navgraph)) if m.navgraph else "")
        base = cls(
            **where,
            furniture=tuple(scn.actors.furniture),
            people=tuple(scn.actors.people),
            n_furniture=scn.actors.random_furniture,
            n_people=scn.actors.random_people,
            start_nodes=(scn.mission.start_node,) if scn.mission.start_node >= 0 else (),
            goal_nodes=tuple(scn.mission.waypoints),
            # The mission's time limit in steps (a step is frames_per_step camera frames).
            max_steps=max(1, math.ceil(scn.mission.max_duration_s * scn.kinect.rate_hz / _frames_per_step(changes) - 1e-9)),
            world=scn.world,
            robot=scn.robot,
            odometry=scn.odometry,
            kinect=scn.kinect,
            fspf=scn.fspf,
            localization=scn.localization,
            avoidance=scn.avoidance,
            navigator=scn.navigator,
        )
        return base.replace(**changes)


def _frames_per_step(changes: dict[str, Any]) -> int:
    """``frames_per_step`` among a scenario's changes (1 when absent or invalid: the
    check of the fields then names it)."""
    v = changes.get("frames_per_step", 1)
    return v if isinstance(v, int) and not isinstance(v, bool) and v >= 1 else 1


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

