"""Scenario files: one TOML per runnable experiment, parsed strictly into dataclasses.

A scenario names a map, the robot and sensor configuration, actors, a mission, a seed
and what to report. Paths in a scenario are relative to the scenario file; a map given
by ``name`` is one of the buildings shipped in ``sim/assets``; a ``vectormap`` without a
``navgraph`` gets a graph made from its walls (cached beside the map file).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from autonomy.common.errors import InputError
from autonomy.localization.cgr import CGRConfig
from autonomy.navigation.avoidance import AvoidanceConfig
from autonomy.navigation.config import NavigatorConfig
from autonomy.perception.fspf import FSPFConfig
from autonomy.perception.nearfield import NearField
from autonomy.stack import LocalizationConfig as StackLocalizationConfig
from autonomy.stack import RecoveryConfig, StackConfig
from sim.config import apply_overrides, from_dict, read_toml
from sim.experiments.expect import Expectation, parse_expectations
from sim.simulator.actors import Furniture, Person
from sim.simulator.blueprints import ASSETS_DIR, BuildingConfig
from sim.simulator.fault_config import FaultsConfig
from sim.simulator.irregular import Irregularity
from sim.simulator.kinect import KinectConfig
from sim.simulator.robot import OdometryConfig, RobotConfig, avoidance_for_body
from sim.simulator.world import WorldConfig

#: Scenario files shipped with the project (the repo's scenarios/ folder).
SCENARIOS_DIR = Path(__file__).resolve().parent.parent / "scenarios"

MISSION_KINDS = ("waypoints",)
FOLLOWERS = ("navigator", "ground_truth")
#: map.free_space: an open map, a closed one, or told from the walls.
FREE_SPACE = ("auto", "open", "closed")


@dataclass(frozen=True)
class MapConfig:
    """Which building: a shipped asset by name, explicit files, or a generated one."""

    name: str = ""
    """A building in sim/assets (e.g. corridor_loop, small_floor)."""
    vectormap: str = ""
    """Path to a *.vectormap.txt / *.vectormap.json (relative to the scenario file)."""
    navgraph: str = ""
    """Path to a *.navigation.json (relative to the scenario file); empty with a
    ``vectormap``: a graph made from the walls, cached as <map>.auto.navigation.json."""
    generate_seed: int = -1
    """>= 0: draw a procedural building with this seed instead (sim.simulator.blueprints)."""
    irregular: bool = True
    """With ``generate_seed``: walls drawn as irregularly as a real floor plan's (skewed
    a degree or so, corners jittered, recesses, jogs, doubled lines;
    :class:`sim.simulator.irregular.Irregularity`); false: exactly square."""

    free_space: str = "auto"
    """With ``vectormap``: where the robot may be. ``closed``: only what the walls enclose
    (a building); ``open``: everything within the walls' convex hull (a parking lot, a
    yard: walls that enclose no inside); ``auto``: open when the walls are sparse or
    enclose almost nothing (:mod:`autonomy.maps.freespace`). The graph made from the walls and
    the places of random furniture follow it."""

    def __post_init__(self) -> None:
        if self.free_space not in FREE_SPACE:
            raise InputError(f"map.free_space {self.free_space!r}: expected one of {', '.join(FREE_SPACE)}")
        if self.free_space != "auto" and not self.vectormap:
            raise InputError("map.free_space: only a map given as 'vectormap' can be declared open or closed")
        given = sum([bool(self.name), bool(self.vectormap), self.generate_seed >= 0])
        if given != 1:
            raise InputError("map: give exactly one of 'name', 'vectormap' (optionally with 'navgraph') or 'generate_seed'")
        if self.navgraph and not self.vectormap:
            raise InputError("map.navgraph: give it with 'vectormap' (the map it belongs to)")
        if not self.irregular and self.generate_seed < 0:
            raise InputError("map.irregular: only a generated building ('generate_seed') can be drawn square or irregular")

    @property
    def open_map(self) -> bool | None:
        """``free_space`` as :attr:`autonomy.maps.freespace.FreeSpaceConfig.open_map`."""
        return {"auto": None, "open": True, "closed": False}[self.free_space]

    def building_config(self) -> BuildingConfig:
        """The generator's configuration for ``generate_seed`` (irregular or square)."""
        return BuildingConfig() if self.irregular else BuildingConfig(irregularity=Irregularity.none())


@dataclass(frozen=True)
class ActorsConfig:
    """Unmapped furniture and walking people."""

    furniture: tuple[Furniture, ...] = ()
    """Explicit furniture pieces."""
    people: tuple[Person, ...] = ()
    """Explicit people with routes."""
    random_furniture: int = 0
    """Extra furniture pieces placed at random in the map's open areas."""
    random_people: int = 0
    """Extra people walking random nav-graph routes."""

    def __post_init__(self) -> None:
        if self.random_furniture < 0 or self.random_people < 0:
            raise InputError("actors: random_furniture and random_people must be >= 0")


@dataclass(frozen=True)
class MissionConfig:
    """What the robot does."""

    kind: str = "waypoints"
    """waypoints: drive through nav-graph nodes in sequence."""
    waypoints: tuple[int, ...] = ()
    """Nav-graph node ids to visit; empty = draw ``n_random_waypoints`` at random."""
    n_random_waypoints: int = 4
    """How many random waypoints when none are given."""
    start_node: int = -1
    """Node id to start at; -1 = the first waypoint's graph neighbour / a random node."""
    follower: str = "navigator"
    """navigator: drives on the localization estimate; ground_truth: the same navigator on
    the true pose (for tests of everything but localization)."""
    max_duration_s: float = 120.0
    """Stop after this much simulated time."""
    target_distance_m: float = 0.0
    """Long run: keep drawing random waypoints until the robot has driven this far
    (0 = visit the given / drawn waypoints once)."""
    waypoint_timeout_s: float = 0.0
    """A waypoint not reached within this time counts as failed; 0 = automatic: 30 s plus
    twice the nominal time of the leg's plan at cruise speed, re-armed with what is left
    of the plan when the navigator re-plans round a block (at most three times the first
    budget; :func:`sim.experiments.waypoints.follow_plan`)."""

    def __post_init__(self) -> None:
        if self.target_distance_m < 0:
            raise InputError("mission.target_distance_m: expected a number >= 0")
        if self.kind not in MISSION_KINDS:
            raise InputError(f"mission.kind {self.kind!r}: expected one of {', '.join(MISSION_KINDS)}")
        if self.follower not in FOLLOWERS:
            raise InputError(f"mission.follower {self.follower!r}: expected one of {', '.join(FOLLOWERS)}")
        if self.waypoint_timeout_s < 0:
            raise InputError("mission.waypoint_timeout_s: expected a number >= 0 (0 = automatic)")
        if self.max_duration_s <= 0:
            raise InputError("mission.max_duration_s: expected a positive number")
        if self.n_random_waypoints < 1 and not self.waypoints:
            raise InputError("mission.n_random_waypoints: expected >= 1 when no waypoints are given")


#: CGR's motion noise parameters, set from the odometry's when ``localization.calibrated_motion``.
MOTION_NOISE_KEYS = ("alpha1", "alpha2_rad_per_m", "alpha3")


@dataclass(frozen=True)
class LocalizationConfig(StackLocalizationConfig):
    """The robot stack's CGR localization (BV2012, IV), plus the run's check against the truth."""

    reset_error_m: float = 1.0
    """Error above which the run counts a localization failure (the paper's threshold:
    its operator then re-localized the robot by hand, a "reset")."""
    recovered_error_m: float = 0.5
    """A failure is over when the error is back below this."""
    truth_reset_after_s: float = 60.0
    """A failure the robot has not recovered from itself within this long is ended by
    re-initialising the belief at the true pose, as the paper's operator did; the run
    counts it in ``truth_resets_needed``. 0 = at once (the paper's protocol)."""
    start_known: bool = True
    """The robot starts knowing its pose (false: it relocalizes on the map first)."""
    calibrated_motion: bool = False
    """True: CGR's motion noise is the simulated odometry's own (``cgr.alpha1`` its
    ``rotation_noise``, ``cgr.alpha3`` its ``translation_noise``, ``cgr.alpha2_rad_per_m``
    its ``rotation_per_translation_rad_per_m``), as a robot's motion model is calibrated
    to its wheels. The defaults of ``cgr`` are the original code's, for CoBot's wheels (5
    degrees of heading a metre): on the simulated odometry, which turns the heading only
    when the robot turns, the belief's spread grows ten times faster than its error on a
    straight drive without a wall in view, and the lost detection's spread test stops the
    robot to look round an atrium where it can see nothing. Off by default: with it, the
    shipped 200 m long run scraped a wall (docs/results.md, "Real floors")."""

    def __post_init__(self) -> None:
        if not isinstance(self.calibrated_motion, bool):
            raise InputError(f"localization.calibrated_motion: expected true or false, got {self.calibrated_motion!r}")
        if self.calibrated_motion:
            default = CGRConfig()
            for name in MOTION_NOISE_KEYS:
                if getattr(self.cgr, name) != getattr(default, name):
                    raise InputError(
                        f"localization.cgr.{name} is set while localization.calibrated_motion = true (the motion noise is "
                        "the simulated odometry's); set calibrated_motion = false to give your own"
                    )
        if not self.reset_error_m > 0:
            raise InputError("localization.reset_error_m: expected a positive number")
        if not 0 < self.recovered_error_m <= self.reset_error_m:
            raise InputError("localization.recovered_error_m: expected a positive number no larger than reset_error_m")
        if not (math.isfinite(self.truth_reset_after_s) and self.truth_reset_after_s >= 0):
            raise InputError("localization.truth_reset_after_s: expected a number of seconds >= 0")


def robot_localization(loc: LocalizationConfig, odometry: OdometryConfig) -> StackLocalizationConfig:
    """The robot stack's localization section of a simulated robot: the simulation's own
    keys (the truth's thresholds) left out, and CGR's motion noise the odometry's when
    ``loc.calibrated_motion``."""
    out = StackLocalizationConfig(**{f.name: getattr(loc, f.name) for f in dataclasses.fields(StackLocalizationConfig)})
    if loc.calibrated_motion:
        cgr = dataclasses.replace(
            out.cgr, alpha1=odometry.rotation_noise, alpha2_rad_per_m=odometry.rotation_per_translation_rad_per_m,
            alpha3=odometry.translation_noise,
        )
        out = dataclasses.replace(out, cgr=cgr)
    return out


@dataclass(frozen=True)
class ReportConfig:
    """What a run writes besides report.json."""

    figures: bool = True
    """Write PNG figures (trajectory over the map)."""
    rrd_every: int = 15
    """Log heavy items (depth, point clouds) to rerun every Nth frame."""
    rrd_depth_downsample: int = 2
    """Log depth to rerun at 1/k of the camera resolution."""
    progress: bool = True
    """Show a progress bar on a terminal."""
    incident_seconds: float = 8.0
    """The flight recorder keeps this many seconds before each collision incident
    (``incidents.json``, ``incidents.png``)."""
    trace_s: tuple[float, ...] = ()
    """[from, to] seconds: write ``trace.jsonl``, one record per frame in that window
    (truth, belief, health, navigation: :mod:`sim.experiments.trace`); empty: none."""
    checkpoint_s: float = 60.0
    """Every this many simulated seconds, write report.json of what has finished so far
    (marked ``"interrupted": true`` with a ``checkpoint`` block), so that a run killed
    without warning (SIGKILL, a machine going down) keeps its metrics and events up to
    the last checkpoint; the final report replaces it. 0: no checkpoints."""

    def __post_init__(self) -> None:
        if not (isinstance(self.checkpoint_s, (int, float)) and math.isfinite(self.checkpoint_s) and self.checkpoint_s >= 0):
            raise InputError(f"report.checkpoint_s: expected a number of seconds >= 0 (0: no checkpoints), got {self.checkpoint_s!r}")
        if self.rrd_every < 1 or self.rrd_depth_downsample < 1:
            raise InputError("report: rrd_every and rrd_depth_downsample must be >= 1")
        if not (isinstance(self.incident_seconds, (int, float)) and math.isfinite(self.incident_seconds) and self.incident_seconds > 0):
            raise InputError(f"report.incident_seconds: expected a positive number of seconds, got {self.incident_seconds!r}")
        w = self.trace_s
        if w and not (len(w) == 2 and all(math.isfinite(v) for v in w) and 0.0 <= w[0] < w[1]):
            raise InputError(f"report.trace_s: expected [from, to] seconds with 0 <= from < to, got {list(w)!r}")


@dataclass(frozen=True)
class DriverConfig:
    """What drives the robot: the project's robot stack, or your own
    (:mod:`autonomy.stack.driver`)."""

    factory: str = ""
    """Empty: :class:`autonomy.stack.RobotStack`. Else the function that makes your
    :class:`autonomy.stack.driver.Driver` from a
    :class:`autonomy.stack.driver.DriverSetup`: ``package.module:function`` (importable)
    or ``file.py:function`` (relative to the scenario file)."""


@dataclass(frozen=True)
class Scenario:
    """A runnable scenario (see scenarios/*.toml)."""

    name: str
    """Short name used in reports."""
    description: str = ""
    """One line shown by ``depthnav scenarios``."""
    seed: int = 0
    """Master seed: every random draw of the run derives from it."""
    map: MapConfig = field(default_factory=lambda: MapConfig(name="small_floor"))
    world: WorldConfig = field(default_factory=WorldConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    kinect: KinectConfig = field(default_factory=KinectConfig)
    fspf: FSPFConfig = field(default_factory=FSPFConfig)
    localization: LocalizationConfig = field(default_factory=LocalizationConfig)
    navigator: NavigatorConfig = field(default_factory=NavigatorConfig)
    avoidance: AvoidanceConfig = field(default_factory=AvoidanceConfig)
    actors: ActorsConfig = field(default_factory=ActorsConfig)
    mission: MissionConfig = field(default_factory=MissionConfig)
    faults: FaultsConfig = field(default_factory=FaultsConfig)
    """Injected faults (sim.simulator.fault_config, applied by sim.simulator.faults): none by default."""
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)
    """The robot stack's lost detection, relocalization and mount check."""
    report: ReportConfig = field(default_factory=ReportConfig)
    driver: DriverConfig = field(default_factory=DriverConfig)
    """What drives the robot (``[driver] factory = "..."``: your own stack)."""
    expect: tuple[Expectation, ...] = ()
    """What the run must achieve, checked on its report (the ``[expect]`` table of
    metric = condition: :mod:`sim.experiments.expect`); none: a run passes when it ends."""
    base_dir: str = ""
    """Directory that relative paths resolve against (set by the loader)."""

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise InputError(f"seed: expected an integer >= 0, got {self.seed!r}")
        # The stack avoids with the body the simulator drives: one radius, robot.radius_m.
        object.__setattr__(self, "avoidance", avoidance_for_body(self.avoidance, self.robot, "scenario"))
        if self.driver.factory and self.mission.follower != "navigator":
            raise InputError(
                f"mission.follower = {self.mission.follower!r} drives the project's navigator on the true pose; "
                "a [driver] of your own gets no truth (use follower = 'navigator')"
            )
        if not self.localization.start_known and not self.driver.factory and not (self.localization.enabled and self.recovery.enabled):
            raise InputError(
                "localization.start_known = false: a robot that does not know where it starts must find itself on the map; "
                "it needs localization.enabled and recovery.enabled"
            )

    def stack_config(self) -> StackConfig:
        """The robot stack's configuration: the camera as the Kinect model defines it (one
        source for its intrinsics, mount and range), FSPF, localization (CGR's motion
        noise the odometry's, ``localization.calibrated_motion``), avoidance and the
        navigator."""
        loc = robot_localization(self.localization, self.odometry)
        return StackConfig(self.kinect.depth_camera(), self.fspf, loc, self.avoidance, self.navigator, recovery=self.recovery)

    def resolve(self, path: str) -> Path:
        p = Path(path)
        return p if p.is_absolute() else Path(self.base_dir or ".") / p


def load_scenario(path: str | Path, overrides: list[str] | None = None) -> Scenario:
    """Read and strictly parse a scenario file, applying ``--set`` overrides."""
    path = Path(path)
    src = str(path)
    data = read_toml(path)
    if "base_dir" in data:
        raise InputError(f"{src}: unknown key 'base_dir' (it is set from the file's location)")
    if data.get("kind", "mission") != "mission":
        raise InputError(f"{src}: key 'kind': this is a {data['kind']!r} experiment, not a mission scenario")
    data.pop("kind", None)
    data = apply_overrides(data, overrides or [])
    if isinstance(data.get("avoidance"), dict) and "robot_radius_m" in data["avoidance"]:
        raise InputError(f"{src}: key 'avoidance.robot_radius_m': set 'robot.radius_m' (the stack avoids with the simulated body's radius)")
    data["base_dir"] = str(path.resolve().parent)
    scn = with_expectations(from_dict, Scenario, data, src)
    # Map files must exist now, not halfway through a run.
    for key in ("vectormap", "navgraph"):
        value = getattr(scn.map, key)
        if value and not scn.resolve(value).is_file():
            raise InputError(f"{src}: key 'map.{key}': file not found: {scn.resolve(value)}")
    if scn.driver.factory:
        from sim.experiments.driver_stack import load_factory

        load_factory(scn.driver.factory, scn.base_dir, src)  # found now, not when the run starts
    if scn.map.name and not (ASSETS_DIR / f"{scn.map.name}.vectormap.txt").is_file():
        names = ", ".join(sorted(p.name.removesuffix(".vectormap.txt") for p in ASSETS_DIR.glob("*.vectormap.txt")))
        raise InputError(f"{src}: key 'map.name': no building {scn.map.name!r} in sim/assets (have: {names})")
    # The near field depends on the camera, its mount and the sensor's range: check the
    # combination now (a few ms), not when the run starts.
    try:
        cam = scn.kinect.depth_camera()
        NearField(cam.intrinsics, cam.mount, cam.min_range_m, scn.avoidance.robot_radius_m, scn.avoidance.near_field)
    except InputError as err:
        raise InputError(f"{src}: {err}") from None
    return scn


def with_expectations(build, cls: type, data: dict, source: str):
    """``build(cls, data, source=...)`` with the ``[expect]`` table parsed apart: its keys
    are report metrics, not fields (:func:`sim.experiments.expect.parse_expectations`)."""
    table = data.pop("expect", None)
    cfg = build(cls, data, source=source)
    if table is None:
        return cfg
    return dataclasses.replace(cfg, expect=parse_expectations(table, source))


def list_scenarios(directory: Path = SCENARIOS_DIR) -> list[tuple[Path, str]]:
    """(path, description) of every scenario file in a directory."""
    out = []
    for p in sorted(directory.glob("*.toml")):
        try:
            desc = tomllib.loads(p.read_text(encoding="utf-8")).get("description", "")
        except (tomllib.TOMLDecodeError, UnicodeDecodeError):
            desc = "(unreadable TOML)"
        out.append((p, str(desc)))
    return out
