"""Closed-loop runs of scenarios: world, robot, Kinect, mission, metrics and reports.

One control tick is one Kinect frame (1/30 s): people move, the controller sets the
velocity command, physics advances, the depth frame is rendered and noised, odometry
integrates. Every stage is timed. A run writes ``report.json`` (the contract in the
README), a trajectory figure, the ground-truth trajectory in TUM format and, on request,
a rerun recording. Ctrl-C stops a run early and still writes what it measured.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from autonomy.avoidance import obstacle_points
from autonomy.cgr import CGRLocalizer
from autonomy.errors import InputError
from autonomy.fspf import fspf
from autonomy.navigator import Navigator, in_camera_view
from autonomy.nearfield import NearField
from autonomy.observation import correspond
from autonomy.planner import astar, path_points
from autonomy.raycast import SceneQuery, load_or_build
from autonomy.vectormap import NavGraph, VectorMap, load_navgraph, load_vectormap
from sim.config import to_dict
from sim.experiments.blackbox import (
    INCIDENT_GAP_S,
    FlightRecorder,
    render_incidents,
    starts_incident,
)
from sim.scenario import ASSETS_DIR, Scenario
from sim.simulator.actors import Furniture, Person, point_segment_distance
from sim.simulator.kinect import KinectCamera
from sim.simulator.kinect_noise import apply_kinect_noise
from sim.simulator.robot import Odometry
from sim.simulator.world import World, build_world

#: Report schema version (bump when keys change meaning).
REPORT_VERSION = 1

#: The paper's figures for scenarios that reproduce one of its experiments (seed 000).
PAPER_FIGURES: dict[str, dict[str, float]] = {
    # VI-B: the long-run trial drove over 4 km with 3 localization resets.
    "long_run": {"distance_m": 4000.0, "resets": 3, "resets_per_km": 0.75},
    # The demo is that trial shortened; the paper's rate is the figure to compare.
    "demo": {"distance_m": 4000.0, "resets": 3, "resets_per_km": 0.75},
}


@dataclass
class Building:
    """A map with its graph, (if known) its zones, and the map file it came from."""

    vectormap: VectorMap
    navgraph: NavGraph
    open_areas: tuple[tuple[float, float, float, float], ...] = ()
    rooms: tuple[tuple[float, float, float, float], ...] = ()
    map_path: Path | None = None


def load_building(scn: Scenario) -> Building:
    """The building a scenario names (shipped asset, files, or a generated one)."""
    from sim.simulator import blueprints

    m = scn.map
    if m.generate_seed >= 0:
        bp = blueprints.generate_building(blueprints.BuildingConfig(), m.generate_seed)
        return Building(bp.vectormap, bp.navgraph, tuple(bp.open_areas), tuple(bp.rooms))
    if m.name:
        bp = blueprints.load_blueprint(ASSETS_DIR / m.name)
        return Building(bp.vectormap, bp.navgraph, tuple(bp.open_areas), tuple(bp.rooms), ASSETS_DIR / f"{m.name}.vectormap.txt")
    path = scn.resolve(m.vectormap)
    return Building(load_vectormap(path), load_navgraph(scn.resolve(m.navgraph)), map_path=path)


def random_furniture(
    building: Building, n: int, rng: np.random.Generator, robot_radius_m: float = 0.3
) -> tuple[Furniture, ...]:
    """Furniture dropped in open areas (or rooms), clear of walls and of nav-graph edges.

    Each piece keeps its half-diagonal plus the robot radius plus 15 cm from every graph
    edge, so the graph stays drivable, and 5 cm from every wall.
    """
    zones = building.open_areas or building.rooms
    if n == 0:
        return ()
    if not zones:
        raise InputError("actors.random_furniture: the map has no open areas or rooms to place furniture in")
    edges = building.navgraph.edge_segments()
    walls = np.asarray(building.vectormap.segments)
    kinds = ("table", "chair", "box", "cabinet")
    out: list[Furniture] = []
    for _ in range(500 * n):
        if len(out) == n:
            break
        z = zones[rng.integers(len(zones))]
        kind = str(kinds[rng.integers(len(kinds))])
        f = Furniture(kind=kind, x=float(rng.uniform(z[0], z[2])), y=float(rng.uniform(z[1], z[3])), yaw=float(rng.uniform(-math.pi, math.pi)))
        half_diag = 0.5 * math.hypot(f.dims[0], f.dims[1])
        p = np.array([f.x, f.y])
        if len(edges) and point_segment_distance(p, edges).min() < half_diag + robot_radius_m + 0.15:
            continue
        if len(walls) and point_segment_distance(p, walls).min() < half_diag + 0.05:
            continue
        if any(math.hypot(o.x - f.x, o.y - f.y) < half_diag + 0.5 * math.hypot(*o.dims[:2]) + 0.1 for o in out):
            continue
        out.append(f)
    if len(out) < n:
        raise InputError(f"actors.random_furniture: only {len(out)} of {n} pieces fit in the map's open areas clear of the nav graph")
    return tuple(out)


def random_people(graph: NavGraph, n: int, rng: np.random.Generator) -> tuple[Person, ...]:
    """People walking back and forth along random shortest paths of the nav graph."""
    out = []
    ids = graph.node_ids()
    for _ in range(n):
        for _attempt in range(20):
            a, b = (int(v) for v in rng.choice(ids, 2, replace=False))
            try:
                path = astar(graph, a, b)
            except InputError:
                continue
            pts = path_points(graph, path)
            if len(pts) >= 2 and np.sum(np.hypot(*np.diff(pts, axis=0).T)) > 3.0:
                # Walk slightly right of the centreline so robots and people can pass.
                route = tuple((float(x), float(y)) for x, y in pts)
                out.append(Person(route=route, speed_mps=float(rng.uniform(0.9, 1.4)), start_offset_m=float(rng.uniform(0, 20))))
                break
    return tuple(out)


@dataclass
class Mission:
    """Waypoint sequence and the follower's state."""

    waypoints: list[int]
    start_pose: np.ndarray
    current: int = 0
    started_at: float = 0.0
    timeout_s: float = 0.0
    events: list[dict] = field(default_factory=list)


def plan_mission(scn: Scenario, graph: NavGraph, rng: np.random.Generator) -> Mission:
    """Waypoints (given or random) and the start pose on the first path edge."""
    m = scn.mission
    ids = [int(i) for i in graph.node_ids()]
    known = set(ids)
    for w in m.waypoints:
        if w not in known:
            raise InputError(f"mission.waypoints: node id {w} is not in the navigation graph")
    if m.start_node >= 0 and m.start_node not in known:
        raise InputError(f"mission.start_node: node id {m.start_node} is not in the navigation graph")
    if m.waypoints:
        wps = list(m.waypoints)
    else:
        wps = []
        prev = m.start_node if m.start_node >= 0 else None
        # A long run draws one waypoint at a time until it has driven its distance.
        n_first = 1 if m.target_distance_m > 0 else m.n_random_waypoints
        while len(wps) < n_first:
            c = int(rng.choice(ids))
            if c != prev:
                wps.append(c)
                prev = c
    start = m.start_node if m.start_node >= 0 else None
    if start is None:
        nbrs = graph.neighbors(wps[0])
        start = int(nbrs[0]) if nbrs else wps[0]
        if len(wps) == 1 and start == wps[0]:
            raise InputError("mission: a single waypoint with no graph neighbour; give mission.start_node")
    xy = graph.node_xy()
    p = xy[graph.index_of(start)]
    q = xy[graph.index_of(wps[0])]
    heading = math.atan2(q[1] - p[1], q[0] - p[0]) if np.hypot(*(q - p)) > 1e-6 else 0.0
    mission = Mission(waypoints=wps, start_pose=np.array([p[0], p[1], heading]))
    return mission


def write_tum(path: Path, t: np.ndarray, poses: np.ndarray) -> None:
    """Trajectory in TUM format: ``timestamp x y z qx qy qz qw`` per line."""
    with open(path, "w", encoding="utf-8") as f:
        f.write("# timestamp x y z qx qy qz qw\n")
        for ti, p in zip(t, poses, strict=True):
            f.write(f"{ti:.6f} {p[0]:.6f} {p[1]:.6f} 0.000000 0.000000 0.000000 {math.sin(p[2] / 2):.9f} {math.cos(p[2] / 2):.9f}\n")


def _median_ms(xs: list[float]) -> float:
    return float(np.median(xs) * 1000.0) if xs else 0.0


def _people_in_view(people: np.ndarray, pose: np.ndarray, scn: Scenario) -> np.ndarray:
    """Which people stand inside the camera's horizontal view (field of view, minimum and
    maximum range; occlusion ignored), for the collision log's ``person_in_view_s_ago``."""
    c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
    rel = people[:, :2] - pose[None, :2]
    x = c * rel[:, 0] + s * rel[:, 1] - scn.navigator.camera_forward_m
    return in_camera_view(x, -s * rel[:, 0] + c * rel[:, 1], scn.navigator)


def collision_incidents(events: list[dict], gap_s: float = INCIDENT_GAP_S) -> int:
    """Encounters behind the contact events (``sim.experiments.blackbox.starts_incident``)."""
    last: dict[tuple, float] = {}
    return sum(starts_incident(last, e, gap_s) for e in events)


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
    ss = np.random.SeedSequence(seed)
    rng_actors, rng_mission, rng_odom, rng_noise = (np.random.default_rng(s) for s in ss.spawn(4))
    noise_base, fspf_base = (int(v) for v in rng_noise.integers(0, 2**31, size=2))

    building = load_building(scn)
    vm, graph = building.vectormap, building.navgraph
    furniture = tuple(scn.actors.furniture) + random_furniture(building, scn.actors.random_furniture, rng_actors, scn.robot.radius_m)
    people = tuple(scn.actors.people) + random_people(graph, scn.actors.random_people, rng_actors)
    mission = plan_mission(scn, graph, rng_mission)
    world: World = build_world(
        vm,
        world=scn.world,
        robot=scn.robot,
        intrinsics=scn.kinect.intrinsics,
        mount=scn.kinect.mount,
        furniture=furniture,
        people=people,
        start_pose=tuple(mission.start_pose),
    )
    camera = KinectCamera(world.model, world.camera_id, scn.kinect)
    odom = Odometry(scn.odometry, rng_odom, mission.start_pose)
    lcfg = scn.localization
    localizer = None
    if lcfg.enabled:
        rng_loc = np.random.default_rng(ss.spawn(1)[0])
        query = SceneQuery(vm, load_or_build(vm, building.map_path, lcfg.grid))
        localizer = CGRLocalizer(lambda x, y: query.scene_lines(x, y)[0], lcfg.cgr, lcfg.observation, rng_loc)
        localizer.reset(mission.start_pose)
    estimates: list[np.ndarray] = [mission.start_pose.copy()]
    loc_errors: list[float] = []
    heading_errors: list[float] = []
    resets = 0
    reset_points: list[np.ndarray] = []
    navigator = Navigator(graph, scn.navigator, scn.avoidance, walls=np.asarray(vm.segments))
    near_field = NearField(scn.kinect.intrinsics, scn.kinect.mount, scn.kinect.noise.min_range_m, scn.avoidance.robot_radius_m, scn.avoidance.near_field)
    use_estimate = scn.mission.follower == "navigator" and localizer is not None

    frame_dt = 1.0 / scn.kinect.rate_hz
    n_sub = max(1, round(frame_dt / scn.world.timestep_s))

    recorder = None
    if rrd or spawn:
        from sim.viz.recording import Recorder

        recorder = Recorder(
            rrd,
            spawn=spawn,
            every=scn.report.rrd_every,
            depth_downsample=scn.report.rrd_depth_downsample,
            recording_id=f"{scn.name}-{seed}",
        )
        recorder.log_map(vm, graph, scn.world.wall_height_m)
        recorder.log_camera_model(scn.kinect.intrinsics, scn.kinect.mount)
        recorder.log_robot_shape(scn.robot.radius_m, scn.robot.height_m)
        recorder.log_furniture(
            [(np.array([f.x, f.y, f.dims[2] / 2]), np.array(f.dims) / 2, f.yaw) for f in furniture]
        )
        recorder.log_waypoints(path_points(graph, mission.waypoints))

    timing: dict[str, list[float]] = {k: [] for k in ("physics", "render", "noise", "fspf", "localization", "navigation", "viz")}
    fspf_counts: list[tuple[int, int, int, int]] = []  # plane points, outliers, planes, 2D points
    times: list[float] = []
    truth: list[np.ndarray] = []
    collisions = 0
    reached = failed = 0
    distance = 0.0
    frame = 0
    interrupted = False
    nav_cfg = scn.navigator

    def leg_timeout(length_m: float) -> float:
        if scn.mission.waypoint_timeout_s > 0:
            return scn.mission.waypoint_timeout_s
        return 30.0 + 2.0 * length_m / nav_cfg.cruise_speed_mps

    mission.timeout_s = leg_timeout(navigator.set_goal(mission.waypoints[0], mission.start_pose, 0.0))
    mission.started_at = 0.0
    max_frames = int(math.ceil(scn.mission.max_duration_s / frame_dt))
    long_run = scn.mission.target_distance_m > 0
    node_ids = [int(i) for i in graph.node_ids()]

    show = progress if progress is not None else (scn.report.progress and sys.stderr.isatty())
    bar = None
    if show:
        from tqdm import tqdm

        bar = tqdm(total=max_frames, unit="frame", desc=scn.name, leave=False)
    wall_start = time.perf_counter()
    pose = world.robot.pose(world.data)
    truth.append(pose)
    times.append(0.0)
    # The first frame, so the navigator sees before it moves.
    depth = apply_kinect_noise(camera.render_clean(world.data), scn.kinect.intrinsics, scn.kinect.noise, noise_base % (2**31))
    planes = fspf(depth, scn.kinect.intrinsics, scn.fspf, seed=fspf_base, mount=scn.kinect.mount)
    obstacles = obstacle_points(np.vstack([planes.points, planes.outliers]), scn.avoidance)
    near_lines = near_field.sight_lines(depth)
    nav = None
    nav_states: dict[str, int] = {}
    near_frames = 0  # frames the near field (obstacles closer than the camera's range) counted
    n_people = len(world.people.people)
    last_in_view = np.full(n_people, -np.inf)
    blackbox = FlightRecorder(scn.report.incident_seconds, scn.kinect.rate_hz)
    try:
        while frame < max_frames and mission.current < len(mission.waypoints):
            t = world.data.time
            t0 = time.perf_counter()
            pose = world.robot.pose(world.data)
            control_pose = estimates[-1] if use_estimate else pose
            nav = navigator.command(control_pose, obstacles, t, near_lines)
            nav_states[nav.state] = nav_states.get(nav.state, 0) + 1
            near_frames += int(nav.near_points > 0)
            timed_out = t - mission.started_at > mission.timeout_s
            if nav.state == "arrived" or timed_out:
                node = mission.waypoints[mission.current]
                goal_xy = graph.node_xy()[graph.index_of(node)]
                # The navigator arrives on its estimate; the run checks the truth.
                ok = nav.state == "arrived" and np.hypot(*(goal_xy - pose[:2])) < nav_cfg.arrival_radius_m + 0.5
                reached += int(ok)
                failed += int(not ok)
                mission.events.append(
                    {
                        "t": round(t, 3),
                        "waypoint": node,
                        "status": "reached" if ok else ("timeout" if timed_out else "wrong_place"),
                        "leg_s": round(t - mission.started_at, 3),
                        "distance_m": round(distance, 2),
                    }
                )
                mission.current += 1
                mission.started_at = t
                if long_run and distance < scn.mission.target_distance_m and mission.current >= len(mission.waypoints):
                    nxt = node
                    while nxt == node:
                        nxt = int(rng_mission.choice(node_ids))
                    mission.waypoints.append(nxt)
                if mission.current >= len(mission.waypoints):
                    break
                mission.timeout_s = leg_timeout(navigator.set_goal(mission.waypoints[mission.current], control_pose, t))
                nav = navigator.command(control_pose, obstacles, t, near_lines)
            cmd = nav.velocity
            world.robot.command(world.data, cmd, frame_dt)
            t1 = time.perf_counter()
            timing["navigation"].append(t1 - t0)
            world.people.update(world.data, t + frame_dt, pose[:2])
            if n_people:
                last_in_view[_people_in_view(world.people.positions(), pose, scn)] = t + frame_dt
            new_events = world.step_frame(n_sub)
            blackbox.push(world.data.time, world.robot.pose(world.data), control_pose, nav, cmd, obstacles, world.people.positions())
            if new_events:
                # What the robot was doing: the navigator's state and the direction it was
                # told to move in (robot frame, degrees), to tell blind-zone contacts apart.
                for ev in world.collision_log[-new_events:]:
                    ev["nav_state"] = nav.state
                    ev["cmd_dir_deg"] = round(math.degrees(math.atan2(cmd[1], cmd[0])), 1) if np.hypot(cmd[0], cmd[1]) > 1e-6 else None
                    for b in ev["bodies"]:
                        if b.startswith("person_"):
                            ev["person_in_view_s_ago"] = round(t + frame_dt - float(last_in_view[int(b[7:])]), 2)
                blackbox.on_events(world.collision_log[-new_events:])
            collisions += new_events
            t2 = time.perf_counter()
            clean = camera.render_clean(world.data)
            t3 = time.perf_counter()
            depth = apply_kinect_noise(clean, scn.kinect.intrinsics, scn.kinect.noise, (noise_base + frame) % (2**31))
            t4 = time.perf_counter()
            planes = fspf(depth, scn.kinect.intrinsics, scn.fspf, seed=fspf_base + frame, mount=scn.kinect.mount)
            p2d, _ = planes.projected(scn.fspf.max_vertical_normal_angle_rad)
            t4b = time.perf_counter()
            fspf_counts.append((len(planes.points), len(planes.outliers), planes.planes, len(p2d)))
            obstacles = obstacle_points(np.vstack([planes.points, planes.outliers]), scn.avoidance)
            near_lines = near_field.sight_lines(depth)
            new_pose = world.robot.pose(world.data)
            increment = odom.update(new_pose)
            t4c = time.perf_counter()
            if localizer is not None:
                localizer.predict(increment)
                p2d, n2d = planes.projected(scn.fspf.max_vertical_normal_angle_rad)
                localizer.update(p2d, n2d)
                est = localizer.estimate()
                err = float(np.hypot(*(est.pose[:2] - new_pose[:2])))
                loc_errors.append(err)
                heading_errors.append(abs(math.atan2(math.sin(est.pose[2] - new_pose[2]), math.cos(est.pose[2] - new_pose[2]))))
                estimates.append(est.pose.copy())
                if err > lcfg.reset_error_m:
                    resets += 1
                    reset_points.append(new_pose[:2].copy())
                    localizer.reset(new_pose)
            t4d = time.perf_counter()
            distance += float(np.hypot(*(new_pose[:2] - pose[:2])))
            truth.append(new_pose)
            times.append(world.data.time)
            frame += 1
            if recorder is not None:
                recorder.set_time(frame, world.data.time)
                recorder.log_pose(frame, new_pose)
                if localizer is not None:
                    recorder.log_estimate(frame, estimates[-1])
                if recorder.heavy(frame):
                    recorder.log_depth(depth)
                    recorder.log_fspf(planes)
                    if localizer is not None:
                        recorder.log_localization(localizer.before_refinement, localizer.after_refinement, localizer.refined_weights)
                        est_pose = estimates[-1]
                        lines = query.scene_lines(float(est_pose[0]), float(est_pose[1]))[0]
                        idx = np.full(len(p2d), -1, dtype=np.int64)
                        if len(lines) and len(p2d):
                            ocfg = lcfg.observation
                            correspond(
                                np.ascontiguousarray(lines), est_pose, np.ascontiguousarray(p2d, dtype=np.float64),
                                np.ascontiguousarray(n2d, dtype=np.float64), True, math.cos(ocfg.theta_max_rad), ocfg.max_distance_m, idx,
                            )
                        recorder.log_scene(lines, est_pose, p2d, idx)
                    recorder.log_near_field(near_lines)
                    if nav is not None and nav.fan is not None:
                        recorder.log_avoidance(
                            nav.fan[0], nav.fan[1], nav.theta_star_rad, nav.desired_rad, navigator.avoid.radius_m
                        )
                    recorder.log_people(world.people.positions())
                    recorder.log_scalars(
                        {
                            "speed_mps": float(np.hypot(*world.robot.velocity_body(world.data)[:2])),
                            "timing_ms/render": (t3 - t2) * 1e3,
                            "timing_ms/noise": (t4 - t3) * 1e3,
                            "timing_ms/fspf": (t4b - t4) * 1e3,
                            "fspf/plane_points": float(len(planes.points)),
                            "fspf/points_2d": float(len(p2d)),
                            "timing_ms/localization": (t4d - t4c) * 1e3,
                            "localization/error_m": loc_errors[-1] if loc_errors else float("nan"),
                            "localization/spread_m": localizer.estimate().std_xy_m if localizer else float("nan"),
                            "timing_ms/physics": (t2 - t1) * 1e3,
                            "collisions": float(collisions),
                        }
                    )
            t5 = time.perf_counter()
            timing["physics"].append(t2 - t1)
            timing["render"].append(t3 - t2)
            timing["noise"].append(t4 - t3)
            timing["fspf"].append(t4b - t4)
            timing["localization"].append(t4d - t4c)
            timing["viz"].append(t5 - t4d)
            if bar is not None:
                bar.update(1)
                if frame % 30 == 0:
                    bar.set_postfix(dist=f"{distance:.0f}m", wp=f"{reached}/{len(mission.waypoints)}", coll=collisions, resets=resets)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - wall_start
    sim_time = float(world.data.time)
    unvisited = len(mission.waypoints) - mission.current  # not attempted to the end (time ran out)
    truth_arr = np.array(truth)
    metrics = {
        "frames": frame,
        "distance_m": round(distance, 4),
        "duration_s": round(sim_time, 4),
        "collisions": collisions,
        **{f"collisions_{k}": sum(k in c["with"] for c in world.collision_log) for k in ("wall", "furniture", "person")},
        "collision_incidents": collision_incidents(world.collision_log),
        "waypoints_reached": reached,
        "waypoints_failed": failed,
        "waypoints_unvisited": unvisited,
        "realtime_factor": round(sim_time / wall, 4) if wall > 0 else 0.0,
        "wall_time_s": round(wall, 3),
    }
    if recorder is not None:
        # Time spent logging (in the loop, and flushing the recording at the end) over the
        # time of the rest of the loop (issue #8: at most 0.2).
        t_close = time.perf_counter()
        recorder.close()
        flush_s = time.perf_counter() - t_close
        viz_s = float(np.sum(timing["viz"]))
        metrics["recording_flush_s"] = round(flush_s, 3)
        metrics["logging_overhead"] = round((viz_s + flush_s) / max(wall - viz_s, 1e-9), 4)
    if loc_errors:
        e = np.array(loc_errors)
        metrics.update(
            {
                "resets": resets,
                "resets_per_km": round(resets / max(distance / 1000.0, 1e-9), 4),
                "loc_error_mean_m": round(float(e.mean()), 4),
                "loc_error_median_m": round(float(np.median(e)), 4),
                "loc_error_p95_m": round(float(np.percentile(e, 95)), 4),
                "loc_error_max_m": round(float(e.max()), 4),
                "loc_heading_error_mean_deg": round(math.degrees(float(np.mean(heading_errors))), 3),
            }
        )
    if fspf_counts:
        c = np.array(fspf_counts, dtype=np.float64)
        metrics.update(
            {
                "fspf_plane_points_mean": round(float(c[:, 0].mean()), 2),
                "fspf_outliers_mean": round(float(c[:, 1].mean()), 2),
                "fspf_planes_mean": round(float(c[:, 2].mean()), 2),
                "fspf_points_2d_mean": round(float(c[:, 3].mean()), 2),
            }
        )
    files = {"report": "report.json", "trajectory_truth": "trajectory_truth.tum"}
    write_tum(out / files["trajectory_truth"], np.array(times), truth_arr)
    if localizer is not None:
        files["trajectory_estimate"] = "trajectory_estimate.tum"
        write_tum(out / files["trajectory_estimate"], np.array(times[: len(estimates)]), np.array(estimates))
    if scn.report.figures:
        from sim.viz.maps import render_map

        render_map(
            vm,
            out / "trajectory.png",
            graph,
            trajectories={"ground truth": truth_arr[:, :2], **({"CGR estimate": np.array(estimates)[:, :2]} if localizer is not None else {})},
            markers={"waypoints": path_points(graph, mission.waypoints), **({"resets": np.array(reset_points)} if reset_points else {})},
            title=f"{scn.name} (seed {seed}): {distance:.0f} m, {resets} resets, {collisions} contacts in {metrics['collision_incidents']} incidents",
        )
        files["trajectory_figure"] = "trajectory.png"
    if blackbox.incidents:
        files["incidents"] = "incidents.json"
        (out / files["incidents"]).write_text(json.dumps({"seconds": scn.report.incident_seconds, "incidents": blackbox.incidents}) + "\n", encoding="utf-8")
        if scn.report.figures:
            render_incidents(blackbox.incidents, np.asarray(vm.segments), out / "incidents.png", scn.robot.radius_m)
            files["incidents_figure"] = "incidents.png"
    if recorder is not None:
        if rrd:
            files["recording"] = str(Path(rrd).resolve().relative_to(out.resolve())) if Path(rrd).resolve().is_relative_to(out.resolve()) else str(rrd)
    backend = camera.backend_name if camera._backend is not None else "none"
    camera.close()
    report = {
        "version": REPORT_VERSION,
        "scenario": scn.name,
        "seed": seed,
        "interrupted": interrupted,
        "metrics": metrics,
        "paper": PAPER_FIGURES.get(scn.name, {}),
        "timing_ms": {k: round(_median_ms(v), 4) for k, v in timing.items()},
        "render_backend": backend,
        "map": {"segments": vm.n_segments, "nodes": len(graph.nodes), "edges": len(graph.edges)},
        "actors": {"furniture": len(furniture), "people": len(people)},
        "waypoints": mission.waypoints,
        "navigation": {"states": nav_states, "replans": navigator.replans, "recoveries": navigator.recoveries, "near_field_frames": near_frames},
        "events": mission.events,
        "collision_events": world.collision_log,
        "files": files,
        "config": {k: v for k, v in to_dict(scn).items() if k != "base_dir"},
    }
    (out / "report.json").write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    return report
