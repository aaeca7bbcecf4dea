"""A mission run's site, set up from its scenario and seed: the building, the actors, the
mission, the MuJoCo world, the simulator step and the robot stack, and the
:class:`Run` record the closed loop (:mod:`sim.experiments.loop`) fills in. The run
reads the stack only through its outputs (:class:`autonomy.stack.StackOutput`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from autonomy.common.errors import InputError
from autonomy.maps.vectormap import load_navgraph, load_vectormap
from autonomy.perception.camera import DepthCamera
from autonomy.stack import RobotStack, StackOutput
from autonomy.stack.driver import DriverSetup
from sim.experiments.blackbox import FlightRecorder
from sim.experiments.columns import Column
from sim.experiments.driver_stack import DriverStack, load_factory
from sim.experiments.waypoints import Mission, plan_mission
from sim.rosbag.run_bag import RunBag
from sim.scenario import Scenario
from sim.simulator import blueprints
from sim.simulator.actors import Furniture, Person
from sim.simulator.blueprints import ASSETS_DIR
from sim.simulator.building import Building, navgraph_from_walls, random_furniture, random_people
from sim.simulator.fault_config import fault_actors, fault_rng
from sim.simulator.faults import FaultInjector
from sim.simulator.kinect import KinectCamera
from sim.simulator.robot import Odometry
from sim.simulator.step import EpisodeSeeds, SimStep
from sim.simulator.world import World, build_world

#: Stages timed every frame, in the order of the report's ``timing_ms``.
STAGES = ("physics", "render", "noise", "fspf", "obstacles", "localization", "navigation", "viz")


def load_building(scn: Scenario) -> Building:
    """The building a scenario names (shipped asset, files, or a generated one). A vector
    map without a navigation graph gets one made from its walls for the scenario's robot
    radius, cached beside the map (:func:`sim.simulator.building.navgraph_from_walls`)."""
    m = scn.map
    if m.generate_seed >= 0:
        bp = blueprints.generate_building(m.building_config(), m.generate_seed)
        return Building(bp.vectormap, bp.navgraph, tuple(bp.open_areas), tuple(bp.rooms))
    if m.name:
        bp = blueprints.load_blueprint(ASSETS_DIR / m.name)
        return Building(bp.vectormap, bp.navgraph, tuple(bp.open_areas), tuple(bp.rooms), ASSETS_DIR / f"{m.name}.vectormap.txt")
    path = scn.resolve(m.vectormap)
    vm = load_vectormap(path)
    graph = load_navgraph(scn.resolve(m.navgraph)) if m.navgraph else navgraph_from_walls(vm, path, scn.avoidance, open_map=m.open_map)
    return Building(vm, graph, map_path=path, open_map=m.open_map)


@dataclass
class Run:
    """A scenario's site and robot, set up for one seed, and what the loop records."""

    scn: Scenario
    seed: int
    seeds: EpisodeSeeds
    building: Building
    furniture: tuple[Furniture, ...]
    people: tuple[Person, ...]
    mission: Mission
    world: World
    sim: SimStep
    stack: RobotStack | DriverStack
    """The project's robot stack, or the scenario's own driver in its place."""
    out: StackOutput
    """The stack's last output (its command drives the next physics step)."""
    use_estimate: bool
    """The navigator drives on the CGR estimate (else on the truth: ``ground_truth`` follower)."""
    # What the loop records.
    frames: int = 0
    distance_m: float = 0.0
    collisions: int = 0
    # Per-frame records are typed columns that keep all but their newest rows on disk
    # (:mod:`sim.experiments.columns`), so a run's memory does not grow with its length.
    times: Column = field(default_factory=Column)
    truth: Column = field(default_factory=lambda: Column(3))
    estimates: Column = field(default_factory=lambda: Column(3))
    loc_errors: Column = field(default_factory=Column)
    heading_errors: Column = field(default_factory=Column)
    fspf_counts: Column = field(default_factory=lambda: Column(4, np.int32))
    nav_states: dict[str, int] = field(default_factory=dict)
    near_frames: int = 0
    timing: dict[str, Column] = field(default_factory=lambda: {k: Column(None, np.float32) for k in STAGES})
    rss_mb: list[tuple[int, float, float]] = field(default_factory=list)
    """(frame, resident memory in MB, distance driven), sampled every ``sim.experiments.loop.RSS_EVERY`` frames."""
    last_in_view: np.ndarray = field(default_factory=lambda: np.zeros(0))
    blackbox: FlightRecorder | None = None
    failures: list[dict] = field(default_factory=list)
    """Localization failures (error above ``reset_error_m``): when, how large, how they ended."""
    truth_resets: int = 0
    """Failures ended by re-initialising at the true pose (the robot did not recover itself)."""
    health_frames: dict[str, int] = field(default_factory=dict)
    """Frames spent in each of the stack's health states."""
    tracked_m: float = 0.0
    """Metres driven while CGR tracked the belief (not relocalizing) ..."""
    blind_m: float = 0.0
    """... of them without an observation update: the belief dead-reckoned (no wall in
    view, or too few points matched)."""
    blind_stretch_m: float = 0.0
    """Metres driven since CGR's last observation update (or relocalization) ..."""
    blind_stretch_max_m: float = 0.0
    """... and the longest such stretch of the run."""
    faults: FaultInjector | None = None
    """The fault injector when the scenario has faults."""
    crash: dict | None = None
    """Where and how the loop stopped on an error (None when it did not)."""
    crash_exc: Exception | None = None
    """That error."""
    rejected: list[tuple[float, str]] = field(default_factory=list)
    """(time, why) of each frame the stack did not use (dropped, invalid, stale)."""
    bag: RunBag | None = None
    """Writes the run as a ROS 2 bag (``depthnav run --bag``), when asked."""
    trace: list[str] = field(default_factory=list)
    """JSON lines of the ``report.trace_s`` window (:mod:`sim.experiments.trace`), kept
    as text: a window the length of a 4 km run is then a few hundred bytes a frame."""

    @property
    def resets(self) -> int:
        """The paper's count: localization failures (error above ``reset_error_m``) not
        caused by an injected fault (a kidnapping is meant to make one)."""
        return sum(f.get("fault") is None for f in self.failures)

    @property
    def recovering(self) -> bool:
        """A localization failure is open (by the truth) or the robot is relocalizing."""
        open_failure = bool(self.failures) and self.failures[-1]["end_t"] is None
        return open_failure or self.out.relocalizing

    @property
    def driven_by_own_stack(self) -> bool:
        """A scenario's own driver drives (no CGR inside to account for)."""
        return isinstance(self.stack, DriverStack)

    @property
    def localizing(self) -> bool:
        return self.out.localizing

    @property
    def camera(self) -> KinectCamera:
        return self.sim.camera

    @cached_property
    def robot_camera(self) -> DepthCamera:
        """The camera as the robot stack knows it (field of view, mount, range)."""
        return self.scn.kinect.depth_camera()


def driver_stack(scn: Scenario, vectormap, graph, seed: int) -> DriverStack:
    """The scenario's own driver (``[driver] factory``) made for this run, as the loop's stack."""
    factory = load_factory(scn.driver.factory, scn.base_dir, scn.name)
    setup = DriverSetup(
        vectormap=vectormap, navgraph=graph, camera=scn.kinect.depth_camera(), robot_radius_m=scn.robot.radius_m,
        max_speed_mps=scn.robot.max_speed_mps, max_angular_rad_s=scn.robot.max_angular_rad_s,
        frame_rate_hz=scn.kinect.rate_hz, seed=int(seed),
    )
    try:
        driver = factory(setup)
    except Exception as exc:  # the user's code: named, in one line
        raise InputError(f"{scn.name}: driver.factory {scn.driver.factory!r} raised {type(exc).__name__}: {exc}") from None
    return DriverStack(driver, setup, scn.navigator, scn.driver.factory)


def build_run(scn: Scenario, seed: int) -> Run:
    """Building, furniture, people and mission from the seed; the world, the simulator
    step and the robot stack, at the mission's start."""
    seeds = EpisodeSeeds.from_seed(seed)
    building = load_building(scn)
    graph = building.navgraph
    furniture = tuple(scn.actors.furniture) + random_furniture(building, scn.actors.random_furniture, seeds.actors, scn.robot.radius_m)
    people = tuple(scn.actors.people) + random_people(graph, scn.actors.random_people, seeds.actors, building.main_node_ids)
    if scn.faults.enabled:
        # Bodies the faults move in (a blockage's panels, a crowd), parked outside.
        extra_furniture, extra_people = fault_actors(scn.faults)
        furniture, people = furniture + extra_furniture, people + extra_people
    mission = plan_mission(scn.mission, graph, seeds.mission)
    # The robot's stack first: a driver of the user's that fails to start is then one line,
    # with no world or render process made.
    scfg = scn.stack_config()
    stack: RobotStack | DriverStack
    if scn.driver.factory:
        stack = driver_stack(scn, building.vectormap, graph, seed)
        start_known = scn.localization.start_known
    else:
        stack = RobotStack(building.vectormap, graph, scfg, rng=seeds.localization, fspf_seed=seeds.fspf_seed, map_path=building.map_path)
        start_known = scn.localization.start_known or not scfg.recovers
    stack.prepare_recovery()
    out = stack.reset(mission.start_pose if start_known else None)
    world = build_world(
        building.vectormap, world=scn.world, robot=scn.robot, intrinsics=scn.kinect.intrinsics, mount=scn.kinect.mount,
        furniture=furniture, people=people, start_pose=tuple(mission.start_pose),
    )
    camera = KinectCamera(world.model, world.camera_id, scn.kinect)
    sim = SimStep(world, camera, Odometry(scn.odometry, seeds.odometry, mission.start_pose), seeds.noise_seed)
    use_estimate = scn.mission.follower == "navigator" and out.localizing
    run = Run(scn, seed, seeds, building, furniture, people, mission, world, sim, stack, out, use_estimate)
    run.last_in_view = np.full(len(world.people.people), -np.inf)
    run.blackbox = FlightRecorder(scn.report.incident_seconds, scn.kinect.rate_hz)
    if scn.faults.enabled:
        run.faults = FaultInjector(
            scn.faults, world, building, fault_rng(seed), sim.odometry, scn.robot.radius_m, until_m=scn.mission.target_distance_m
        )
    run.estimates.append(mission.start_pose.copy())
    return run
