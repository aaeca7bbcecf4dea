"""Closed-loop runs of mission scenarios: build the site, drive the loop, report.

One control tick is one Kinect frame (1/30 s). The robot stack decides on the last frame
(:class:`autonomy.stack.RobotStack`), the simulator steps once with its command
(:class:`sim.simulator.step.SimStep`: people, physics, the noisy depth frame, odometry),
and the stack perceives and localizes on the new frame. Every stage is timed. A run
writes ``report.json`` (the contract in the README), a trajectory figure, the true and
estimated trajectories in TUM format and, on request, a rerun recording. Ctrl-C stops a
run early and still writes what it measured; so does an error inside the loop, which
then also writes its traceback to ``crash.txt`` and raises :class:`RunCrashed`.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from autonomy.common.geometry import wrap_angle
from autonomy.maps.planner import path_points
from autonomy.maps.vectormap import load_navgraph, load_vectormap
from autonomy.navigation.config import NavCommand
from autonomy.navigation.surroundings import in_camera_view
from autonomy.stack import RobotStack
from sim.config import to_dict
from sim.experiments.blackbox import (
    INCIDENT_GAP_S,
    FlightRecorder,
    render_incidents,
    starts_incident,
)
from sim.experiments.columns import Column
from sim.experiments.kinds import crash_block, stopped, write_crash
from sim.experiments.memory import release_free_memory, resident_mb
from sim.experiments.report_file import write_json
from sim.experiments.trace import TRACE_FILE, in_window, trace_record, write_trace
from sim.experiments.waypoints import Mission, close_leg, follow_plan, plan_mission, start_leg
from sim.scenario import Scenario
from sim.simulator import blueprints
from sim.simulator.actors import Furniture, Person, furniture_body, person_index
from sim.simulator.blueprints import ASSETS_DIR
from sim.simulator.building import Building, navgraph_from_walls, random_furniture, random_people
from sim.simulator.faults import FaultInjector, fault_actors, fault_rng
from sim.simulator.kinect import KinectCamera
from sim.simulator.robot import Odometry
from sim.simulator.step import EpisodeSeeds, SimFrame, SimStep
from sim.simulator.world import World, build_world

#: Report schema version (bump when keys change meaning).
REPORT_VERSION = 1

#: The paper's figures for scenarios that reproduce one of its experiments (BV2012).
PAPER_FIGURES: dict[str, dict[str, float]] = {
    # VI-B: the long-run trial drove over 4 km with 3 localization resets.
    "long_run": {"distance_m": 4000.0, "resets": 3, "resets_per_km": 0.75},
    # The demo is that trial shortened; the paper's rate is the figure to compare.
    "demo": {"distance_m": 4000.0, "resets": 3, "resets_per_km": 0.75},
}

#: Resident memory is sampled, after the free heap is returned to the system, every this
#: many frames (30 s of simulated time).
RSS_EVERY = 900
#: The report's frame times at the start and the end of a run are medians over this many frames.
ENDS_FRAMES = 2000


def resources(run: Run) -> dict:
    """Memory and per-frame time at the start and the end of a run, to show nothing grows
    over a long one: resident MB at the first and last samples and at the peak (and, from
    2 km on, the median over the first and over the last kilometre), the samples against
    the distance driven, and the median frame time (all stages) over the first and last
    ``ENDS_FRAMES`` frames."""
    out: dict = {}
    if run.rss_mb:
        mb = [m for _, m, _ in run.rss_mb]
        out.update(rss_start_mb=round(mb[0], 1), rss_end_mb=round(mb[-1], 1), rss_peak_mb=round(max(mb), 1))
        # The curve itself, every RSS_EVERY frames: [distance m, resident MB].
        out["rss_by_distance"] = [[round(d, 1), round(m, 1)] for _, m, d in run.rss_mb]
        # The first and the last kilometre of a long run (the start includes the warm-up).
        if run.distance_m >= 2000.0:
            first = [m for _, m, d in run.rss_mb if d <= 1000.0]
            last = [m for _, m, d in run.rss_mb if d >= run.distance_m - 1000.0]
            if first and last:
                out.update(rss_first_km_mb=round(float(np.median(first)), 1), rss_last_km_mb=round(float(np.median(last)), 1))
    n = len(run.timing["physics"])
    if n:
        total = np.sum([np.asarray(run.timing[k]) for k in STAGES], axis=0) * 1e3
        k = min(ENDS_FRAMES, n)
        out.update(frame_ms_start=round(float(np.median(total[:k])), 3), frame_ms_end=round(float(np.median(total[-k:])), 3))
    return out


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


def write_tum(path: Path, t: np.ndarray, poses: np.ndarray) -> None:
    """Trajectory in TUM format: ``timestamp x y z qx qy qz qw`` per line."""
    with open(path, "w", encoding="utf-8") as f:
        f.write("# timestamp x y z qx qy qz qw\n")
        for ti, p in zip(t, poses, strict=True):
            f.write(f"{ti:.6f} {p[0]:.6f} {p[1]:.6f} 0.000000 0.000000 0.000000 {math.sin(p[2] / 2):.9f} {math.cos(p[2] / 2):.9f}\n")


def collision_incidents(events: list[dict], gap_s: float = INCIDENT_GAP_S) -> int:
    """Encounters behind the contact events (``sim.experiments.blackbox.starts_incident``)."""
    last: dict[tuple, float] = {}
    return sum(starts_incident(last, e, gap_s) for e in events)


# --------------------------------------------------------------------------- the run


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
    stack: RobotStack
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
    """(frame, resident memory in MB, distance driven), sampled every ``RSS_EVERY`` frames."""
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
        return open_failure or self.stack.relocalizing

    @property
    def localizing(self) -> bool:
        return self.stack.localizer is not None

    @property
    def camera(self) -> KinectCamera:
        return self.sim.camera


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
    world = build_world(
        building.vectormap, world=scn.world, robot=scn.robot, intrinsics=scn.kinect.intrinsics, mount=scn.kinect.mount,
        furniture=furniture, people=people, start_pose=tuple(mission.start_pose),
    )
    camera = KinectCamera(world.model, world.camera_id, scn.kinect)
    sim = SimStep(world, camera, Odometry(scn.odometry, seeds.odometry, mission.start_pose), seeds.noise_seed)
    stack = RobotStack(
        building.vectormap, graph, scn.stack_config(), rng=seeds.localization, fspf_seed=seeds.fspf_seed, map_path=building.map_path
    )
    stack.prepare_recovery()
    stack.reset(mission.start_pose if scn.localization.start_known or stack.health is None else None)
    use_estimate = scn.mission.follower == "navigator" and stack.localizer is not None
    run = Run(scn, seed, seeds, building, furniture, people, mission, world, sim, stack, use_estimate)
    run.last_in_view = np.full(len(world.people.people), -np.inf)
    run.blackbox = FlightRecorder(scn.report.incident_seconds, scn.kinect.rate_hz)
    if scn.faults.enabled:
        run.faults = FaultInjector(
            scn.faults, world, building, fault_rng(seed), sim.odometry, scn.robot.radius_m, until_m=scn.mission.target_distance_m
        )
    run.estimates.append(mission.start_pose.copy())
    return run


def run_scenario(
    scn: Scenario,
    out_dir: str | Path,
    *,
    seed: int | None = None,
    rrd: str | Path | None = None,
    spawn: bool = False,
    progress: bool | None = None,
) -> dict:
    """Run a scenario headless and write its report; returns the report dict."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    seed = scn.seed if seed is None else int(seed)
    run = build_run(scn, seed)
    recorder = open_recording(run, rrd, spawn) if (rrd or spawn) else None
    wall_start = time.perf_counter()
    interrupted = drive(run, recorder, progress, lambda: write_checkpoint(run, out, time.perf_counter() - wall_start))
    wall = time.perf_counter() - wall_start
    try:
        if run.crash is None:
            report = finish_report(run, out, recorder, rrd, wall, interrupted)
        else:
            report = crash_report(run, out, recorder, rrd, wall)
    finally:
        run.camera.close()
    write_report(out / "report.json", report)
    if run.crash is not None:
        c = run.crash
        # A user's mistake found only on the way (a waypoint the user's map has no path
        # to) stays the one-line error, with where the finished part was kept.
        assert run.crash_exc is not None
        raise stopped(run.crash_exc, f"the run stopped at t = {c['t']:.2f} s (frame {c['frame']}, {c['distance_m']:.0f} m)", out / "report.json") from None
    return report


def write_report(path: Path, report: dict) -> None:
    """Write report.json whole or not at all (a kill mid-write leaves the one before)."""
    write_json(path, report)


def write_checkpoint(run: Run, out: Path, wall: float) -> None:
    """report.json of what has finished so far (``report.checkpoint_s``): the metrics,
    events and recovery records to this frame, marked interrupted, with where it was
    written; no figures or trajectories (the final report writes them)."""
    report = build_report(run, run_metrics(run, wall), {"report": "report.json"}, True)
    report["checkpoint"] = {"t": round(float(run.world.data.time), 4), "frame": run.frames, "distance_m": round(run.distance_m, 3)}
    write_report(out / "report.json", report)


def finish_report(run: Run, out: Path, recorder, rrd: str | Path | None, wall: float, interrupted: bool) -> dict:
    """Metrics, figures, trajectories and the recording's close: the report dict."""
    metrics = run_metrics(run, wall)
    if recorder is not None:
        metrics.update(close_recording(recorder, run, wall))
    files = write_outputs(run, out, metrics, rrd if recorder is not None else None)
    return build_report(run, metrics, files, interrupted)


def crash_report(run: Run, out: Path, recorder, rrd: str | Path | None, wall: float) -> dict:
    """The report of a run the loop stopped on an error, with the traceback in ``crash.txt``.
    The frame that failed is dropped, so every record ends on the last whole frame; if
    the full report cannot be made from what is left, a short one with the loop's counts
    is written instead of nothing."""
    assert run.crash is not None and run.crash_exc is not None
    write_crash(out, run.crash_exc)
    try:
        report = finish_report(run, out, recorder, rrd, wall, True)
    except Exception as exc:  # the state the error left may not be reportable; the counts are
        run.crash["report_error"] = f"{type(exc).__name__}: {exc}"
        report = {
            "version": REPORT_VERSION, "scenario": run.scn.name, "seed": run.seed, "interrupted": True,
            "metrics": {"frames": run.frames, "distance_m": round(run.distance_m, 4), "collisions": run.collisions,
                        "waypoints_reached": run.mission.reached, "wall_time_s": round(wall, 3)},
            "files": {},
        }
    report["error"] = run.crash
    return report


def note_crash(run: Run, exc: Exception) -> None:
    """Keep where and how the loop stopped, and end every per-frame record on the last
    whole frame (the failed one may have written some of its rows)."""
    run.crash = {
        **crash_block(exc),
        "t": round(float(run.world.data.time), 4), "frame": run.frames, "distance_m": round(run.distance_m, 3),
    }
    run.crash_exc = exc
    for col in (run.times, run.truth, run.estimates):
        col.truncate(run.frames + 1)
    for col in (run.loc_errors, run.heading_errors, run.fspf_counts, *run.timing.values()):
        col.truncate(run.frames)


# --------------------------------------------------------------------------- the loop


def depth_backend_line(name: str, process: bool = True) -> str:
    """How depth frames are made, in words, with the fix when it is the slow fallback."""
    if name == "gl":
        where = "in a render process" if process else "in this process"
        return f"rendered by MuJoCo through OpenGL {where} (MUJOCO_GL={os.environ.get('MUJOCO_GL', 'default')})"
    return ("ray cast on the CPU (no OpenGL context could be made; about 20x slower than rendering: "
            "install Mesa's EGL with `make gl`)")


def _caused_by_interrupt(exc: BaseException) -> bool:
    """Whether a KeyboardInterrupt lies anywhere down ``exc``'s chain of causes."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        if isinstance(cur, KeyboardInterrupt):
            return True
        seen.add(id(cur))
        cur = cur.__cause__ if cur.__cause__ is not None else cur.__context__
    return False


def drive(run: Run, recorder, progress: bool | None, checkpoint: Callable[[], None] | None = None) -> bool:
    """The closed loop until the mission is done or its time is up; True if interrupted.
    ``checkpoint`` is called every ``report.checkpoint_s`` simulated seconds."""
    scn, mission = run.scn, run.mission
    every = scn.report.checkpoint_s if checkpoint is not None else 0.0
    next_checkpoint = every
    max_frames = int(math.ceil(scn.mission.max_duration_s / run.sim.frame_dt))
    show = progress if progress is not None else (scn.report.progress and sys.stderr.isatty())
    bar = None
    if show:
        from tqdm import tqdm

        bar = tqdm(total=max_frames, unit="frame", desc=scn.name, leave=False)
    try:
        first = run.sim.first()
        if progress is not False and scn.report.progress:
            # The depth backend decides the speed of a run by 20x: say which one this is.
            print(f"{scn.name}: depth camera {depth_backend_line(run.camera.backend_name, run.camera.cfg.render_process)}", file=sys.stderr)
        run.truth.append(first.pose)
        run.times.append(0.0)
        # The first frame, so the navigator sees before it moves.
        run.stack.perceive(first.depth)
        length = run.stack.set_goal(mission.goal, 0.0, mission.start_pose)
        start_leg(mission, scn.mission, length, _plan_nodes(run.stack), 0.0, scn.navigator.cruise_speed_mps)
        while run.frames < max_frames and not mission.done:
            if not tick(run, recorder):
                break
            if every > 0 and run.world.data.time >= next_checkpoint:
                assert checkpoint is not None
                try:
                    checkpoint()
                except OSError as exc:
                    # A full disk should not end a long run: the final report is tried anyway.
                    print(f"{scn.name}: could not write the checkpoint report.json ({exc}); the run goes on without checkpoints", file=sys.stderr)
                    every = 0.0
                next_checkpoint = run.world.data.time + every
            if bar is not None:
                bar.update(1)
                if run.frames % 30 == 0:
                    bar.set_postfix(dist=f"{run.distance_m:.0f}m", wp=f"{mission.reached}/{len(mission.waypoints)}", coll=run.collisions, resets=run.resets)
    except KeyboardInterrupt:
        return True
    except Exception as exc:
        # A bug in the loop: report what finished (run_scenario raises after). But Ctrl-C
        # (or SIGTERM) landing inside a numba kernel comes out as a SystemError caused by
        # the KeyboardInterrupt, one or several levels down: an interruption, not a bug.
        if not _caused_by_interrupt(exc):
            note_crash(run, exc)
        return True
    finally:
        if bar is not None:
            bar.close()
    return False


def tick(run: Run, recorder) -> bool:
    """One frame: decide on the last frame, step the simulator, perceive and localize.
    False when the mission has ended this frame."""
    world, stack = run.world, run.stack
    t = float(world.data.time)
    if run.faults is not None:
        nav_ = stack.navigator
        run.faults.before_step(t, run.distance_m, None if nav_ is None or len(nav_.path) < 2 else nav_.path)
    pose = world.robot.pose(world.data)
    control_pose = stack.pose.copy() if run.use_estimate else pose
    override = None if run.use_estimate else pose
    nav = stack.decide(t, override)
    nav_ms = stack.timings_s["navigation"]
    if stack.navigator is not None:
        follow_plan(
            run.mission, run.scn.mission, stack.navigator.plan_nodes, stack.navigator.remaining_m(control_pose), t,
            run.scn.navigator.cruise_speed_mps,
        )
    run.nav_states[nav.state] = run.nav_states.get(nav.state, 0) + 1
    run.near_frames += int(nav.near_points > 0)
    timed_out = t - run.mission.started_at > run.mission.timeout_s
    if nav.state == "arrived" or timed_out:
        nav = next_leg(run, nav, timed_out, pose, control_pose, t, override)
        if nav is None:
            return False
    obstacles = stack.perception.obstacles
    frame = run.sim.step(nav.velocity)
    if run.faults is not None:
        frame = run.faults.filter_frame(frame)
    note_contacts(run, frame, pose, t, nav, control_pose, obstacles)
    stack.perceive(frame.depth)
    run.fspf_counts.append(_fspf_counts(stack))
    stack.localize(frame.increment, frame.t)
    if stack.frame_fault:
        run.rejected.append((frame.t, stack.frame_fault))
    check_localization(run, frame)
    if in_window(run.scn.report.trace_s, frame.t):
        run.trace.append(trace_record(frame.t, frame.pose, stack, nav))
    step_m = float(np.hypot(*(frame.pose[:2] - pose[:2])))
    run.distance_m += step_m
    note_blind(run, step_m)
    run.truth.append(frame.pose)
    run.times.append(frame.t)
    run.frames += 1
    t_viz = time.perf_counter()
    if recorder is not None:
        log_frame(recorder, run, frame, nav)
    timings = {**frame.timings_s, **stack.timings_s, "navigation": nav_ms, "viz": time.perf_counter() - t_viz}
    for k in STAGES:
        run.timing[k].append(timings[k])
    if run.frames % RSS_EVERY == 1:
        # Free heap pages go back to the system first (sim.experiments.memory): a long
        # run's resident memory is then what it uses, not the heap's high-water mark.
        release_free_memory()
        run.rss_mb.append((run.frames, resident_mb(), run.distance_m))
    return True


def next_leg(
    run: Run, nav: NavCommand, timed_out: bool, pose: np.ndarray, control_pose: np.ndarray, t: float, override: np.ndarray | None
) -> NavCommand | None:
    """Close the leg that ended; plan the next one and decide again (None: no more)."""
    scn, mission, stack = run.scn, run.mission, run.stack
    close_leg(
        mission, scn.mission, run.building.navgraph, arrived=nav.state == "arrived", timed_out=timed_out, truth_xy=pose[:2],
        t=t, distance_m=run.distance_m, arrival_radius_m=scn.navigator.arrival_radius_m, rng=run.seeds.mission,
        recovering=run.recovering,
    )
    if mission.done:
        return None
    length = stack.set_goal(mission.goal, t, control_pose)
    start_leg(mission, scn.mission, length, _plan_nodes(stack), t, scn.navigator.cruise_speed_mps)
    return stack.decide(t, override)


def _plan_nodes(stack: RobotStack) -> list[int]:
    """The navigator's plan (graph nodes); none without a navigator."""
    return [] if stack.navigator is None else stack.navigator.plan_nodes


def note_contacts(
    run: Run, frame: SimFrame, pose: np.ndarray, t: float, nav: NavCommand, control_pose: np.ndarray, obstacles: np.ndarray
) -> None:
    """People in view, the flight recorder, and what the robot was doing at each new contact."""
    world = run.world
    t_next = t + run.sim.frame_dt
    if len(run.last_in_view):
        run.last_in_view[_people_in_view(run, world.people.positions(), pose)] = t_next
    cmd = nav.velocity
    assert run.blackbox is not None
    run.blackbox.push(frame.t, frame.pose, control_pose, nav, cmd, obstacles, world.people.positions())
    if frame.new_contacts:
        new = world.collision_log[-frame.new_contacts :]
        # What the robot was doing: the navigator's state and the direction it was told
        # to move in (robot frame, degrees), to tell blind-zone contacts apart.
        for ev in new:
            ev["nav_state"] = nav.state
            ev["cmd_dir_deg"] = round(math.degrees(math.atan2(cmd[1], cmd[0])), 1) if np.hypot(cmd[0], cmd[1]) > 1e-6 else None
            for b in ev["bodies"]:
                j = person_index(b)
                if j is not None:
                    ev["person_in_view_s_ago"] = round(t_next - float(run.last_in_view[j]), 2)
        # Fault-placed furniture stands where the fault put it now, not where it was built.
        run.blackbox.on_events(new, furniture=furniture_now(run) if run.faults is not None else ())
    run.collisions += frame.new_contacts


def furniture_now(run: Run) -> list[tuple[float, float, float, tuple[float, float, float]]]:
    """Every furniture piece as (x, y, yaw, dims) where its body stands now (a fault moves
    some: a blockage's panels), for the incident figures."""
    import mujoco

    model = run.world.model
    out = []
    for i, f in enumerate(run.furniture):
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, furniture_body(i))
        if b < 0:
            out.append((f.x, f.y, f.yaw, f.dims))
            continue
        q = model.body_quat[b]
        yaw = math.atan2(2.0 * (q[0] * q[3] + q[1] * q[2]), 1.0 - 2.0 * (q[2] ** 2 + q[3] ** 2))
        out.append((float(model.body_pos[b][0]), float(model.body_pos[b][1]), yaw, f.dims))
    return out


def _people_in_view(run: Run, people: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Which people stand inside the camera's horizontal view (field of view, minimum and
    maximum range; occlusion ignored), for the collision log's ``person_in_view_s_ago``."""
    cam = run.stack.cfg.camera
    c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
    rel = people[:, :2] - pose[None, :2]
    x = c * rel[:, 0] + s * rel[:, 1] - cam.forward_m
    return in_camera_view(x, -s * rel[:, 0] + c * rel[:, 1], cam)


def _fspf_counts(stack: RobotStack) -> tuple[int, int, int, int]:
    per = stack.perception
    assert per is not None
    return (len(per.planes.points), len(per.planes.outliers), per.planes.planes, len(per.points_2d))


def check_localization(run: Run, frame: SimFrame) -> None:
    """Errors against the truth, and the failures they make: above
    ``localization.reset_error_m`` a failure starts; it ends when the error is back below
    ``recovered_error_m`` (the robot recovered by itself), or after
    ``truth_reset_after_s`` by re-initialising the belief at the true pose (counted in
    ``truth_resets_needed``; the paper's operator did this at once)."""
    stack, loc = run.stack, run.scn.localization
    if stack.localizer is None:
        return
    est = stack.pose
    err = float(np.hypot(*(est[:2] - frame.pose[:2])))
    run.loc_errors.append(err)
    run.heading_errors.append(abs(wrap_angle(est[2] - frame.pose[2])))
    run.estimates.append(est.copy())
    run.health_frames[stack.health_state] = run.health_frames.get(stack.health_state, 0) + 1
    open_ = run.failures[-1] if run.failures and run.failures[-1]["end_t"] is None else None
    t = frame.t
    if open_ is None:
        if err > loc.reset_error_m:
            run.failures.append(
                {"t": round(t, 3), "x": round(float(frame.pose[0]), 3), "y": round(float(frame.pose[1]), 3), "max_error_m": round(err, 3),
                 "noticed_t": round(t, 3) if stack.relocalizing else None, "end_t": None, "ended_by": None,
                 "fault": fault_at(run, t) or unknown_start(run)}
            )
            open_ = run.failures[-1]
    if open_ is None:
        return
    open_["max_error_m"] = max(open_["max_error_m"], round(err, 3))
    if open_["noticed_t"] is None and stack.relocalizing:
        open_["noticed_t"] = round(t, 3)
    if err < loc.recovered_error_m and not stack.relocalizing:
        open_.update(end_t=round(t, 3), ended_by="robot")
    elif t - open_["t"] >= loc.truth_reset_after_s:
        open_.update(end_t=round(t, 3), ended_by="truth")
        run.truth_resets += 1
        stack.relocalize(frame.pose)


def note_blind(run: Run, step_m: float) -> None:
    """Account the frame's ``step_m`` metres to the blind driving figures: metres CGR
    tracked without an observation update, and the longest such stretch. Where the floor
    shows the camera no wall for metres on end, the belief dead-reckons and its error
    grows with the odometry's (a degree of heading costs 17 cm over 10 m)."""
    stack = run.stack
    if stack.localizer is None or stack.relocalizing:
        # The search, not CGR, holds the belief; what it accepts is a fix.
        run.blind_stretch_m = 0.0
        return
    run.tracked_m += step_m
    stats = stack.cgr_stats  # None on a refused frame: dead reckoning as well
    if stats is not None and stats.observation:
        run.blind_stretch_m = 0.0
        return
    run.blind_m += step_m
    run.blind_stretch_m += step_m
    run.blind_stretch_max_m = max(run.blind_stretch_max_m, run.blind_stretch_m)


# --------------------------------------------------------------------------- recording


def open_recording(run: Run, rrd: str | Path | None, spawn: bool):
    """A rerun recording with the static scene: map, camera, robot, furniture, waypoints."""
    from sim.viz.recording import Recorder

    scn = run.scn
    rec = Recorder(rrd, spawn=spawn, every=scn.report.rrd_every, depth_downsample=scn.report.rrd_depth_downsample, recording_id=f"{scn.name}-{run.seed}")
    rec.log_map(run.building.vectormap, run.building.navgraph, scn.world.wall_height_m)
    rec.log_camera_model(scn.kinect.intrinsics, scn.kinect.mount)
    rec.log_robot_shape(scn.robot.radius_m, scn.robot.height_m)
    rec.log_furniture([(np.array([f.x, f.y, f.dims[2] / 2]), np.array(f.dims) / 2, f.yaw) for f in run.furniture])
    rec.log_waypoints(path_points(run.building.navgraph, run.mission.waypoints))
    return rec


def log_frame(rec, run: Run, frame: SimFrame, nav: NavCommand) -> None:
    """This frame's pose and estimate; every ``rrd_every`` frames the heavy items."""
    stack, k = run.stack, run.frames
    rec.set_time(k, frame.t)
    rec.log_pose(k, frame.pose)
    if run.localizing:
        rec.log_estimate(k, run.estimates[-1])
    if not rec.heavy(k):
        return
    per = stack.perception
    rec.log_depth(frame.depth)
    rec.log_fspf(per.planes)
    loc = stack.localizer
    if loc is not None:
        rec.log_localization(loc.before_refinement, loc.after_refinement, loc.refined_weights)
        lines, idx = stack.correspondences()
        rec.log_scene(lines, stack.pose, per.points_2d, idx)
    rec.log_near_field(per.near_lines)
    if nav.fan is not None:
        rec.log_avoidance(nav.fan[0], nav.fan[1], nav.theta_star_rad, nav.desired_rad, stack.cfg.avoidance.radius_m)
    rec.log_people(run.world.people.positions())
    ms = {f"timing_ms/{k}": v * 1e3 for k, v in {**frame.timings_s, **stack.timings_s}.items()}
    rec.log_scalars(
        {
            "speed_mps": float(np.hypot(*run.world.robot.velocity_body(run.world.data)[:2])),
            **ms,
            "fspf/plane_points": float(len(per.planes.points)),
            "fspf/points_2d": float(len(per.points_2d)),
            "localization/error_m": run.loc_errors[-1] if run.loc_errors else float("nan"),
            "localization/spread_m": stack.spread[0] if loc is not None else float("nan"),
            **health_scalars(stack),
            "collisions": float(run.collisions),
        }
    )


#: The health state as a number for the rerun timeline.
HEALTH_CODES = {"ok": 0.0, "blind": 1.0, "lost": 2.0, "relocalizing": 3.0}


def health_scalars(stack: RobotStack) -> dict[str, float]:
    """The health signal for the recording's timeline (autonomy.localization.health)."""
    h = stack.health_sample
    if h is None:
        return {}
    return {
        "health/state": HEALTH_CODES.get(stack.health_state, -1.0),
        "health/explained_fast": h.explained_fast,
        "health/explained_slow": h.explained_slow,
        "health/through_fast": h.through_fast,
        "health/jump_m": h.jump_m,
        "health/view_agree": h.view_agree,
        "health/missing_fast": h.missing_fast,
    }


def close_recording(rec, run: Run, wall_s: float) -> dict:
    """Flush the recording; the logging's share of the loop's time (at most 0.2)."""
    t_close = time.perf_counter()
    rec.close()
    flush_s = time.perf_counter() - t_close
    viz_s = float(np.sum(run.timing["viz"]))
    return {"recording_flush_s": round(flush_s, 3), "logging_overhead": round((viz_s + flush_s) / max(wall_s - viz_s, 1e-9), 4)}


# --------------------------------------------------------------------------- results


#: A localization failure starting within this long after an injected fault began (or
#: while it lasts) is that fault's doing.
FAULT_ATTRIBUTION_S = 30.0
#: A lost alarm is false when the true error is below this when it is raised.
FALSE_ALARM_ERROR_M = 0.5


def fault_events(run: Run) -> list[dict]:
    """The injected faults' events (none without a ``[faults]`` table)."""
    return [] if run.faults is None else run.faults.events


def fault_at(run: Run, t: float) -> str | None:
    """The kind of the injected fault active at ``t`` or begun at most
    ``FAULT_ATTRIBUTION_S`` before it ended (None: no fault)."""
    for ev in reversed(fault_events(run)):
        end = ev["t_end"] if ev.get("t_end") is not None else t
        if ev["t_start"] <= t <= end + FAULT_ATTRIBUTION_S:
            return str(ev["kind"])
    return None


#: A fault counts as noticed by the stack within this long of its start ...
NOTICE_WINDOW_S = 60.0
#: ... and the error after it is the largest over this long once it is over.
AFTER_WINDOW_S = 10.0


def truth_at(run: Run, t: float) -> list[float] | None:
    """The true pose [x, y, theta] of the last frame at or before ``t`` (None before the
    first), rounded to the millimetre. The stack's events carry times rounded to the
    millisecond, so a frame up to half a millisecond after ``t`` counts as at it."""
    k = int(np.searchsorted(np.asarray(run.times), t + 5e-4, side="right")) - 1
    if k < 0 or k >= len(run.truth):
        return None
    return [round(float(v), 3) for v in np.asarray(run.truth[k])[:3]]


def fault_report(run: Run) -> list[dict]:
    """Per injected fault: when it happened and the true pose before and after it started
    (a kidnapping's two places), when the stack noticed it (its first lost, blind or
    mount-corrected event, or a frame it refused, after the start) and the true pose
    then, when it was over for the robot (kidnap: its relocalization; the others: the
    fault's end, then the error back below ``recovered_error_m``), the true error before
    and after, the contacts in between."""
    out = []
    times = np.array(run.times[1 : 1 + len(run.loc_errors)])
    errs = np.array(run.loc_errors)
    ok_m = run.scn.localization.recovered_error_m
    signals = [(e["t"], e["event"]) for e in run.stack.events if e["event"] in ("lost", "blind", "mount corrected")]
    signals += [(t, f"frame {why}") for t, why in run.rejected]
    signals.sort()
    relocs = [e["t"] for e in run.stack.events if e["event"] == "relocalized"]
    for ev in fault_events(run):
        t0 = float(ev["t_start"])
        end = float(ev["t_end"]) if ev.get("t_end") is not None else (float(run.times[-1]) if ev["kind"] != "kidnap" else t0)
        rec = {k: ev[k] for k in ("kind", "t_start", "t_end", "distance_m", "truth_before", "truth_after") if k in ev}
        if ev.get("skipped"):
            rec["skipped"] = ev["skipped"]
        seen = [(t, what) for t, what in signals if t0 <= t <= t0 + NOTICE_WINDOW_S]
        rec["noticed_t"] = round(seen[0][0], 3) if seen else None
        rec["noticed_by"] = seen[0][1] if seen else None
        rec["truth_noticed"] = truth_at(run, seen[0][0]) if seen else None
        k0 = int(np.searchsorted(times, t0)) if len(times) else 0
        rec["error_before_m"] = round(float(errs[max(k0 - 1, 0)]), 3) if len(errs) else None
        if ev["kind"] == "kidnap":
            # Its failure (the error it caused), ended by the robot's relocalization or by the truth.
            mine = [f for f in run.failures if f.get("fault") == "kidnap" and t0 - 1.0 <= f["t"] <= t0 + FAULT_ATTRIBUTION_S]
            if mine and mine[0]["ended_by"] == "truth":
                done, rec["ended_by"] = None, "truth"
            else:
                nxt = min([float(e["t_start"]) for e in fault_events(run) if float(e["t_start"]) > t0], default=math.inf)
                after = [t for t in relocs if t0 <= t < nxt]
                done = after[0] if after else None
                rec["ended_by"] = "robot" if done is not None else None
        else:
            k1 = int(np.searchsorted(times, end))
            back = np.flatnonzero(errs[k1:] < ok_m) if k1 < len(errs) else np.zeros(0, np.int64)
            done = float(times[k1 + int(back[0])]) if len(back) else None
        rec["recovered_t"] = round(done, 3) if done is not None else None
        rec["recovery_s"] = round(done - t0, 3) if done is not None else None
        if done is not None and len(times):
            a, b = np.searchsorted(times, done), np.searchsorted(times, done + AFTER_WINDOW_S)
            rec["error_after_m"] = round(float(errs[a:b].max()), 3) if b > a else None
        last = (done if done is not None else end) + AFTER_WINDOW_S
        rec["contacts"] = sum(t0 <= c["t"] <= last for c in run.world.collision_log)
        out.append(rec)
    return out


def unknown_start(run: Run) -> str | None:
    """"unknown start" while a robot started without its pose has not yet found itself
    (its error then is the search's, not a failure of the paper's kind); else None."""
    if run.scn.localization.start_known or any(e["event"] == "relocalized" for e in run.stack.events) or run.truth_resets:
        return None
    return "unknown start"


def recovery_metrics(run: Run) -> dict:
    """Lost alarms against the truth (false alarms: raised while the error was below
    ``FALSE_ALARM_ERROR_M``; misses: failures the robot never noticed before they ended),
    relocalizations, rejected frames, and the failures' detection and recovery times."""
    stack = run.stack
    times = np.array(run.times[1 : 1 + len(run.loc_errors)])
    errs = np.array(run.loc_errors)
    lost = [e for e in stack.events if e["event"] == "lost"]
    false_alarms = 0
    for e in lost:
        k = int(np.searchsorted(times, e["t"] - 1e-9)) if len(times) else 0
        if k < len(errs) and errs[k] < FALSE_ALARM_ERROR_M:
            false_alarms += 1
    failures = run.failures
    noticed = [f["noticed_t"] - f["t"] for f in failures if f["noticed_t"] is not None]
    recovered = [f["end_t"] - f["t"] for f in failures if f["ended_by"] == "robot"]
    return {
        "loc_failures": len(failures),
        "loc_failures_faults": sum(f.get("fault") is not None for f in failures),
        "lost_alarms": len(lost),
        "lost_false_alarms": false_alarms,
        "lost_misses": sum(f["noticed_t"] is None for f in failures),
        "relocalizations": sum(e["event"] == "relocalized" for e in stack.events),
        "recovered_by_robot": sum(f["ended_by"] == "robot" for f in failures),
        "recovery_time_median_s": round(float(np.median(recovered)), 2) if recovered else None,
        "recovery_time_max_s": round(float(np.max(recovered)), 2) if recovered else None,
        "notice_time_median_s": round(float(np.median(noticed)), 2) if noticed else None,
        "frames_dropped": stack.frames_rejected["dropped"],
        "frames_stale": stack.frames_rejected["stale"],
        "frames_invalid": stack.frames_rejected["invalid"],
        "frames_corrupt": stack.frames_rejected["corrupt"],
        "relocalizing_frames": run.health_frames.get("relocalizing", 0),
        "blind_frames": run.health_frames.get("blind", 0),
        **fault_metrics(fault_report(run)),
    }


def fault_metrics(report: list[dict]) -> dict:
    """Injected faults and kidnappings in numbers: how many, how many recovered, and the
    kidnappings' median and worst time to recover (without truth)."""
    if not report:
        return {}
    kid = [r for r in report if r["kind"] == "kidnap" and not r.get("skipped")]
    times = [r["recovery_s"] for r in kid if r["recovery_s"] is not None]
    return {
        "faults_injected": sum(not r.get("skipped") for r in report),
        "faults_recovered": sum(r["recovered_t"] is not None for r in report if not r.get("skipped")),
        "kidnappings": len(kid),
        "kidnappings_recovered": len(times),
        "kidnap_recovery_median_s": round(float(np.median(times)), 2) if times else None,
        "kidnap_recovery_max_s": round(float(np.max(times)), 2) if times else None,
    }


def run_metrics(run: Run, wall_s: float) -> dict:
    """The report's metrics: distance, contacts, waypoints, speed, localization, FSPF."""
    world, mission = run.world, run.mission
    sim_time = float(world.data.time)
    metrics = {
        "frames": run.frames,
        "distance_m": round(run.distance_m, 4),
        "duration_s": round(sim_time, 4),
        "collisions": run.collisions,
        **{f"collisions_{k}": sum(k in c["with"] for c in world.collision_log) for k in ("wall", "furniture", "person")},
        "collision_incidents": collision_incidents(world.collision_log),
        "waypoints_reached": mission.reached,
        "waypoints_failed": mission.failed,
        "waypoints_unvisited": mission.unvisited,
        "realtime_factor": round(sim_time / wall_s, 4) if wall_s > 0 else 0.0,
        "wall_time_s": round(wall_s, 3),
    }
    if run.loc_errors:
        e = np.array(run.loc_errors)
        metrics.update(
            {
                "resets": run.resets,
                "resets_per_km": round(run.resets / max(run.distance_m / 1000.0, 1e-9), 4),
                "truth_resets_needed": run.truth_resets,
                **recovery_metrics(run),
                "loc_error_mean_m": round(float(e.mean()), 4),
                "loc_error_median_m": round(float(np.median(e)), 4),
                "loc_error_p95_m": round(float(np.percentile(e, 95)), 4),
                "loc_error_max_m": round(float(e.max()), 4),
                "loc_heading_error_mean_deg": round(math.degrees(float(np.mean(run.heading_errors))), 3),
                "blind_share": round(run.blind_m / run.tracked_m, 4) if run.tracked_m > 0 else None,
                "blind_stretch_max_m": round(run.blind_stretch_max_m, 2),
            }
        )
    if run.fspf_counts:
        c = np.array(run.fspf_counts, dtype=np.float64)
        metrics.update(
            {
                "fspf_plane_points_mean": round(float(c[:, 0].mean()), 2),
                "fspf_outliers_mean": round(float(c[:, 1].mean()), 2),
                "fspf_planes_mean": round(float(c[:, 2].mean()), 2),
                "fspf_points_2d_mean": round(float(c[:, 3].mean()), 2),
            }
        )
    return metrics


#: Labels of the trajectory figure's failure markers, by what the failure is put down to.
RESETS_LABEL, FAULTS_LABEL, UNKNOWN_START_LABEL = "resets (the paper's count)", "failures from faults", "unknown start"


def failure_markers(failures: list[dict]) -> dict[str, np.ndarray]:
    """The trajectory figure's markers for where localization failures started: the
    paper's resets (nothing injected behind them) apart from the failures a fault caused
    (a kidnapping is meant to make one) and the error of a robot started without its
    pose before it found itself; empty sets left out."""
    def label(f: dict) -> str:
        why = f.get("fault")
        return RESETS_LABEL if why is None else UNKNOWN_START_LABEL if why == "unknown start" else FAULTS_LABEL

    groups: dict[str, list[list[float]]] = {RESETS_LABEL: [], FAULTS_LABEL: [], UNKNOWN_START_LABEL: []}
    for f in failures:
        groups[label(f)].append([f["x"], f["y"]])
    return {name: np.array(xy) for name, xy in groups.items() if xy}


def failures_title(failures: list[dict]) -> str:
    """The figure title's count of failures: the paper's resets, and the others by kind."""
    n = {name: len(xy) for name, xy in failure_markers(failures).items()}
    others = [f"{n[k]} {k}" for k in (FAULTS_LABEL, UNKNOWN_START_LABEL) if k in n]
    return f"{n.get(RESETS_LABEL, 0)} resets" + (f" (and {', '.join(others)})" if others else "")


def write_outputs(run: Run, out: Path, metrics: dict, rrd: str | Path | None) -> dict[str, str]:
    """Trajectories (TUM), the trajectory figure, the incidents; the files written."""
    scn, graph, vm = run.scn, run.building.navgraph, run.building.vectormap
    files = {"report": "report.json", "trajectory_truth": "trajectory_truth.tum"}
    truth = np.array(run.truth)
    write_tum(out / files["trajectory_truth"], np.array(run.times), truth)
    if run.localizing:
        files["trajectory_estimate"] = "trajectory_estimate.tum"
        write_tum(out / files["trajectory_estimate"], np.array(run.times[: len(run.estimates)]), np.array(run.estimates))
    if scn.report.figures:
        from sim.viz.maps import render_map

        render_map(
            vm,
            out / "trajectory.png",
            graph,
            trajectories={"ground truth": truth[:, :2], **({"CGR estimate": np.array(run.estimates)[:, :2]} if run.localizing else {})},
            markers={"waypoints": path_points(graph, run.mission.waypoints), **failure_markers(run.failures)},
            title=f"{scn.name} (seed {run.seed}): {run.distance_m:.0f} m, {failures_title(run.failures)}, {run.collisions} contacts in {metrics['collision_incidents']} incidents",
        )
        files["trajectory_figure"] = "trajectory.png"
    if scn.report.trace_s:
        files["trace"] = TRACE_FILE
        write_trace(out / TRACE_FILE, run.trace)
    assert run.blackbox is not None
    if run.blackbox.incidents:
        files["incidents"] = "incidents.json"
        write_json(out / files["incidents"], {"seconds": scn.report.incident_seconds, "incidents": run.blackbox.incidents}, indent=None)
        if scn.report.figures:
            render_incidents(run.blackbox.incidents, np.asarray(vm.segments), out / "incidents.png", scn.robot.radius_m, furniture=run.furniture)
            files["incidents_figure"] = "incidents.png"
    if rrd:
        r, o = Path(rrd).resolve(), out.resolve()
        files["recording"] = str(r.relative_to(o)) if r.is_relative_to(o) else str(rrd)
    return files


def build_report(run: Run, metrics: dict, files: dict[str, str], interrupted: bool) -> dict:
    """The report.json contract (README)."""
    scn, graph, nav = run.scn, run.building.navgraph, run.stack.navigator
    assert nav is not None
    return {
        "version": REPORT_VERSION,
        "scenario": scn.name,
        "seed": run.seed,
        "interrupted": interrupted,
        "error": run.crash,
        "metrics": metrics,
        "paper": PAPER_FIGURES.get(scn.name, {}),
        "timing_ms": {k: round(float(np.median(v) * 1000.0) if v else 0.0, 4) for k, v in run.timing.items()},
        "resources": resources(run),
        "render_backend": run.camera.backend_name if run.camera._backend is not None else "none",
        "map": {"segments": run.building.vectormap.n_segments, "nodes": len(graph.nodes), "edges": len(graph.edges)},
        "actors": {"furniture": len(run.furniture), "people": len(run.people)},
        "waypoints": run.mission.waypoints,
        "navigation": {
            "states": run.nav_states, "replans": nav.replans, "recoveries": nav.recoveries, "near_field_frames": run.near_frames,
            "blocked_edges": nav.blocked_edges,
        },
        "events": run.mission.events,
        "recovery": {"events": run.stack.events, "failures": run.failures, "faults": fault_report(run)},
        "collision_events": run.world.collision_log,
        "files": files,
        "config": {k: v for k, v in to_dict(scn).items() if k != "base_dir"},
    }
