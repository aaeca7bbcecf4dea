"""The robot stack on a bag: ``depthnav replay BAG --map MAP``.

Each depth frame of the bag (:mod:`sim.rosbag.reader`) is one step of the robot stack
(:class:`autonomy.stack.RobotStack`: FSPF, CGR, the lost detection and relocalization)
with the odometry increment since the previous frame, as the closed loop steps it in
simulation (:mod:`sim.experiments.loop`); nothing is actuated. The replay writes the
estimate as TUM, a ``report.json`` and, on request, a rerun recording.

For a bag the simulator wrote (``depthnav run --bag``), the replay takes the run's seed,
start and stack configuration from ``/depthnav/run`` and its map from ``/map/walls``:
the same seeds, the same frames, the same stack, so the same estimate. The odometry
reaches the replay as poses (``nav_msgs/Odometry``), and the increments recovered from
them differ from the simulator's in the last bits; the report gives the largest
difference from the run's own estimate (``/cgr/pose``). A run whose operator reset the
belief to the truth (a simulated failure) differs from its first reset on: the bag
holds the truth but the replay, like a robot, never reads it.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from pathlib import Path

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import relative_pose, wrap_angle
from autonomy.maps.vectormap import VectorMap, load_vectormap
from autonomy.perception.camera import DepthCamera
from autonomy.stack import RobotStack, StackConfig
from sim.config import apply_overrides, from_dict, parse_floats, to_dict
from sim.experiments.report import write_report, write_tum
from sim.rosbag import messages as m
from sim.rosbag.reader import DEFAULT_TOPICS, BagSource, BagTopics, open_bag
from sim.simulator.step import EpisodeSeeds


def _stack_config(src: BagSource, scenario: str | None, overrides: list[str]) -> tuple[StackConfig, str]:
    """The stack's configuration and where it came from: a scenario file's, the bag's
    recorded one (a depthnav bag), or the defaults; ``overrides`` (``key=value`` on the
    stack's keys) on top; the camera always the bag's."""
    if scenario:
        from sim.scenario import load_scenario

        cfg, where = load_scenario(scenario, overrides).stack_config(), f"scenario {scenario}"
    else:
        info = src.run_info or {}
        data = info.get("stack") if isinstance(info.get("stack"), dict) else None
        where = f"the bag's {src.topics.run}" if data is not None else "the defaults"
        data = apply_overrides(dict(data or {}), overrides)
        data.pop("camera", None)
        source = f"{src.path}: {where}" + (" with --set" if overrides else "")
        cfg = from_dict(StackConfig, data, source=source)
    old = cfg.camera
    cam = DepthCamera(src.intrinsics, src.mount, old.min_range_m, old.max_range_m)
    return dataclasses.replace(cfg, camera=cam, navigate=False), where


def _map(src: BagSource, map_arg: str | None) -> tuple[VectorMap, Path | None]:
    """The vector map: ``--map``, or the walls the bag carries (``/map/walls``)."""
    if map_arg:
        from sim.simulator.blueprints import ASSETS_DIR

        p = Path(map_arg)
        if not p.exists() and (ASSETS_DIR / f"{map_arg}.vectormap.txt").exists():
            p = ASSETS_DIR / f"{map_arg}.vectormap.txt"
        return load_vectormap(p), p
    walls = None
    for msg in src.messages(src.topics.walls):
        pts = [(p.x, p.y) for mk in msg.markers if mk.ns == "walls" for p in mk.points]
        walls = np.asarray(pts, dtype=np.float64).reshape(-1, 4)
        break
    if walls is None or len(walls) == 0:
        raise InputError(f"{src.path}: no map: give the vector map with --map (the bag has no {src.topics.walls})")
    return VectorMap(walls, name=src.path.stem), None


def _start(src: BagSource, start: np.ndarray | None) -> tuple[np.ndarray | None, str]:
    """Where the robot starts: ``--start``, the run's recorded start, the first ground
    truth, or unknown (the stack then finds itself on the map)."""
    if start is not None:
        return np.asarray(start, dtype=np.float64), "--start"
    info = src.run_info or {}
    if info.get("start_known") and isinstance(info.get("start_pose"), list) and len(info["start_pose"]) == 3:
        return np.asarray(info["start_pose"], dtype=np.float64), f"the bag's {src.topics.run}"
    if info.get("start_known") is False:
        return None, f"unknown (the bag's {src.topics.run})"
    if src.truth_t is not None:
        return src.truth_poses[0].copy(), f"the first {src.topics.truth}"
    return None, "unknown"


def _recorded_estimate(src: BagSource) -> dict[int, np.ndarray]:
    """The estimate the bag recorded at each stamp (a depthnav bag's ``/cgr/pose``)."""
    out = {}
    for msg in src.messages(src.topics.estimate):
        p = msg.pose.pose
        out[m.header_ns(msg.header)] = np.array([p.position.x, p.position.y, m.quaternion_yaw(p.orientation)])
    return out


def replay_bag(
    bag: str | Path,
    out_dir: str | Path,
    *,
    map_path: str | None = None,
    start: np.ndarray | None = None,
    seed: int | None = None,
    scenario: str | None = None,
    overrides: list[str] | None = None,
    topics: BagTopics = DEFAULT_TOPICS,
    mount=None,
    rrd: str | Path | None = None,
    progress: bool = False,
    goal: np.ndarray | None = None,
    graph: str | None = None,
) -> dict:
    """Replay ``bag`` through the robot stack into ``out_dir``; returns the report.
    ``goal`` (x, y): the navigator also decides, towards the graph node nearest it, on
    each frame's estimate (nothing is actuated: its commands go to ``commands.csv``), on
    ``graph`` (a navigation.json) or one made from the map's walls."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    src = open_bag(bag, topics, mount)
    try:
        return _replay(src, out, map_path, start, seed, scenario, list(overrides or []), rrd, progress, goal, graph)
    finally:
        src.close()


def _navgraph(vm: VectorMap, map_file: Path | None, graph: str | None, cfg: StackConfig):
    """The navigation graph for ``--goal``: a file, or one made from the walls."""
    if graph:
        from autonomy.maps.vectormap import load_navgraph

        return load_navgraph(graph)
    from sim.simulator.building import navgraph_from_walls

    return navgraph_from_walls(vm, map_file, cfg.avoidance, quiet=True)


def _replay(src: BagSource, out: Path, map_arg, start, seed, scenario, overrides, rrd, progress, goal=None, graph=None) -> dict:
    cfg, cfg_from = _stack_config(src, scenario, overrides)
    if not cfg.localization.enabled:
        raise InputError("replay: localization.enabled is false; the replay runs the localization")
    vm, map_file = _map(src, map_arg)
    start_pose, start_from = _start(src, start)
    info = src.run_info or {}
    run_seed = int(seed) if seed is not None else int(info.get("seed", 0))
    seeds = EpisodeSeeds.from_seed(run_seed)
    navgraph = None
    if goal is not None:
        if start_pose is None:
            raise InputError("replay: --goal needs a known start (--start x,y,theta): the navigator plans from the estimate")
        cfg = dataclasses.replace(cfg, navigate=True)
        navgraph = _navgraph(vm, map_file, graph, cfg)
    stack = RobotStack(vm, navgraph, cfg, rng=seeds.localization, fspf_seed=seeds.fspf_seed, map_path=map_file)
    if start_pose is None and not cfg.recovers:
        raise InputError("replay: an unknown start needs the recovery (recovery.enabled); give --start x,y,theta")
    stack.prepare_recovery()
    stack.reset(start_pose)
    goal_node = None
    commands: list[tuple] = []
    if navgraph is not None:
        goal_node = navgraph.nearest_node(float(goal[0]), float(goal[1]))
        stack.set_goal(goal_node, float(src.frame_stamps()[0][0]) / 1e9, start_pose)
    recorded = _recorded_estimate(src)
    recorder = None
    if rrd:
        from sim.viz.recording import Recorder

        recorder = Recorder(rrd, every=15)
        recorder.log_map(vm)
        recorder.log_camera_model(cfg.camera.intrinsics, cfg.camera.mount)
    ts, est, truth, errors, dropped = [], [], [], [], 0
    diffs_xy, diffs_th = [], []
    timing = {"fspf": [], "localization": []}
    prev_odom = None
    wall0 = time.perf_counter()
    frames = 0
    interrupted = False
    o = None
    try:
        for f in src.frames():
            if prev_odom is None:
                o = stack.step(f.depth, None, f.t, None, localize=False)
            else:
                o = stack.step(f.depth, relative_pose(prev_odom, f.odom), f.t, None)
            prev_odom = f.odom
            frames += 1
            if o.command is not None:
                v = o.command.velocity
                commands.append((f.t, float(v[0]), float(v[1]), float(v[2]), o.command.state))
            dropped += f.depth is None
            ns = int(round(f.t * 1e9))
            e = np.asarray(o.estimate, dtype=np.float64)
            ts.append(f.t)
            est.append(e)
            for k in timing:
                timing[k].append(o.timings_s.get(k, math.nan))
            tr = src.truth_at(ns)
            if tr is not None:
                truth.append((f.t, tr))
                errors.append(float(np.hypot(*(e[:2] - tr[:2]))))
            rec = recorded.get(ns)
            if rec is not None:
                diffs_xy.append(float(np.hypot(*(e[:2] - rec[:2]))))
                diffs_th.append(abs(wrap_angle(float(e[2] - rec[2]))))
            if recorder is not None:
                recorder.set_time(frames, f.t - ts[0])
                recorder.log_estimate(frames, e)
                if tr is not None:
                    recorder.log_pose(frames, tr)
                if recorder.heavy(frames):
                    if f.depth is not None:
                        recorder.log_depth(f.depth)
                    recorder.log_fspf(o.perception.planes)
            if progress and frames % 300 == 0:
                print(f"replay: {frames} frames, t = {f.t - ts[0]:.1f} s", file=sys.stderr)
    except KeyboardInterrupt:
        interrupted = True
    wall = time.perf_counter() - wall0
    if recorder is not None:
        recorder.close()
    t = np.asarray(ts)
    poses = np.asarray(est).reshape(-1, 3)
    write_tum(out / "trajectory_estimate.tum", t, poses)
    files = {"report": "report.json", "trajectory_estimate": "trajectory_estimate.tum"}
    if truth:
        write_tum(out / "trajectory_truth.tum", np.array([a for a, _ in truth]), np.array([b for _, b in truth]))
        files["trajectory_truth"] = "trajectory_truth.tum"
    if rrd:
        files["rerun"] = str(rrd)
    if goal_node is not None:
        with open(out / "commands.csv", "w", encoding="utf-8") as fh:
            fh.write("t,vx,vy,omega,state\n")
            fh.writelines(f"{c[0]:.6f},{c[1]:.4f},{c[2]:.4f},{c[3]:.4f},{c[4]}\n" for c in commands)
        files["commands"] = "commands.csv"
    duration = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    events = list(o.events) if o is not None else []
    metrics: dict = {
        "frames": frames,
        "frames_without_image": dropped,
        "duration_s": round(duration, 3),
        "wall_time_s": round(wall, 3),
        "frames_per_s": round(frames / wall, 2) if wall > 0 else 0.0,
        "realtime_factor": round(duration / wall, 3) if wall > 0 else 0.0,
        "lost_alarms": sum(e.get("event") == "lost" for e in events),
        "relocalizations": sum(e.get("event") == "relocalized" for e in events),
        "fspf_ms_mean": round(1000.0 * float(np.nanmean(timing["fspf"])), 3) if frames else None,
        "localization_ms_mean": round(1000.0 * float(np.nanmean(timing["localization"])), 3) if frames else None,
    }
    if goal_node is not None:
        states: dict[str, int] = {}
        for c in commands:
            states[c[4]] = states.get(c[4], 0) + 1
        metrics.update({"goal_node": int(goal_node), "nav_states": states, "arrived": bool(commands and commands[-1][4] == "arrived")})
    if errors:
        e = np.asarray(errors)
        metrics.update({
            "loc_error_mean_m": round(float(e.mean()), 4), "loc_error_p95_m": round(float(np.percentile(e, 95)), 4),
            "loc_error_max_m": round(float(e.max()), 4),
        })
    if diffs_xy:
        metrics.update({
            "recorded_estimate_frames": len(diffs_xy),
            "recorded_estimate_max_diff_m": float(max(diffs_xy)),
            "recorded_estimate_max_diff_rad": float(max(diffs_th)),
        })
    report = {
        "bag": str(src.path),
        "interrupted": interrupted,
        "seed": run_seed,
        "start": None if start_pose is None else [round(float(v), 6) for v in start_pose],
        "start_from": start_from,
        "stack_config_from": cfg_from,
        "map": str(map_file) if map_file else f"the bag's walls ({len(vm.segments)} segments)",
        "camera": {"intrinsics": to_dict(cfg.camera.intrinsics), "mount": to_dict(cfg.camera.mount)},
        "topics": to_dict(src.topics),
        "metrics": metrics,
        "events": events,
        "files": files,
    }
    write_report(out / "report.json", report)
    return report


def summary(report: dict) -> str:
    """One line of a replay's report."""
    mt = report["metrics"]
    parts = [f"{mt['frames']} frames ({mt['duration_s']:.1f} s) at {mt['frames_per_s']:.0f} frames/s ({mt['realtime_factor']:.1f}x real time)"]
    if "loc_error_p95_m" in mt:
        parts.append(f"error mean / p95 / max {100 * mt['loc_error_mean_m']:.1f} / {100 * mt['loc_error_p95_m']:.1f} / {100 * mt['loc_error_max_m']:.1f} cm")
    if "recorded_estimate_max_diff_m" in mt:
        parts.append(f"largest difference from the recorded estimate {mt['recorded_estimate_max_diff_m']:.2g} m")
    parts.append(f"lost alarms {mt['lost_alarms']}")
    return "replay: " + ", ".join(parts)


def parse_pose(text: str, option: str) -> np.ndarray:
    """``x,y,theta`` (metres, radians) from the command line."""
    return np.asarray(parse_floats(text, option, 3, "x,y,theta (metres, metres, radians)", "1.0,2.5,0.0"))


def parse_point(text: str, option: str) -> np.ndarray:
    """``x,y`` (metres) from the command line."""
    return np.asarray(parse_floats(text, option, 2, "x,y in metres", "12.5,3.0"))


def parse_mount(text: str):
    """``height,forward,lateral,pitch_deg`` from the command line, as a camera mount."""
    from autonomy.perception.camera import CameraMount

    h, f, lat, pitch = parse_floats(text, "--mount", 4, "height,forward,lateral,pitch_deg (metres, degrees down)", "0.7,0.22,0,17")
    if h <= 0:
        raise InputError(f"--mount {text!r}: the height must be above the floor (> 0)")
    return CameraMount(height_m=h, forward_m=f, lateral_m=lat, pitch_down_rad=math.radians(pitch))
