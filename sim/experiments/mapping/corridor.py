"""PlaneMap Experiment III as the ``mapping_corridor`` kind (III-C, IV-C): the robot
drives a corridor loop with the camera looking right; planes from RANSAC and the
randomized Hough transform are registered into octree maps at the odometry pose (no
loop closure, so the drift shows), exported and drawn; time to the first plane, per
plane, and the maps' sizes."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError, require_int, require_positive
from autonomy.common.geometry import wrap_angle
from autonomy.planes import (
    OctreeConfig,
    PlaneOctree,
    SparseAccumulator,
    accumulator_nbytes,
    dense_accumulator_nbytes,
    depth_to_cloud,
    detection_frame,
    register_planes,
)
from sim.experiments.mapping.common import (
    ALGORITHMS,
    MappingExperiment,
    Stop,
    detect,
    median,
    progress_bar,
    until_stopped,
)
from sim.experiments.mapping.driver import mapping_experiment, run_trial
from sim.experiments.mapping.loop_driver import LoopDriver
from sim.experiments.mapping.plane_maps import draw_maps, map_wall_error
from sim.scenes.corridor import (
    CorridorScene,
    build_corridor_world,
    corridor_path,
    robot_from_camera,
)
from sim.simulator.kinect import KinectCamera
from sim.simulator.robot import Odometry, OdometryConfig, RobotConfig

KIND = "mapping_corridor"

#: IV-C: RANSAC 50 ms to the first plane, Hough 170 ms a plane (Core 2 Duo, 2.8 GHz).
PAPER: dict[str, float] = {"ransac_first_plane_ms": 50.0, "hough_per_plane_ms": 170.0}


@dataclass(frozen=True)
class CorridorExperiment(MappingExperiment):
    """Experiment III: octree plane maps of a corridor loop from odometry (III-C, IV-C)."""

    name: str = KIND
    """Scenario name."""
    scene: CorridorScene = field(default_factory=CorridorScene)
    """Corridor loop and camera placement (looking right, level)."""
    laps: float = 1.0
    """Fraction of laps to drive (1 = once round the loop)."""
    speed_mps: float = 0.5
    """Cruise speed along the loop."""
    map_rate_hz: float = 5.0
    """Frames processed per second (the paper recorded at 5 Hz)."""
    pose_source: str = "odometry"
    """odometry (the paper: no loop closure) or truth (planes at the true pose)."""
    odometry: OdometryConfig = field(
        default_factory=lambda: OdometryConfig(translation_noise=0.1, rotation_noise=0.1, rotation_per_translation_rad_per_m=0.05)
    )
    """Odometry noise (modest; the sim's default is 20% per increment)."""
    robot: RobotConfig = field(default_factory=RobotConfig)
    """The base."""
    octree: OctreeConfig = field(default_factory=OctreeConfig)
    """Map parameters (the ``policy`` named here is the main map; the other is built too)."""
    export: bool = True
    """Write the maps (JSON, PLY, GLB) and the top-view PNG."""
    rrd_every: int = 5
    """With ``--rrd``: log the growing plane maps every this many mapped frames (1 s at 5 Hz)."""

    def __post_init__(self) -> None:
        require_positive(self, "", "laps", "speed_mps", "map_rate_hz")
        require_int(self, "", "rrd_every")
        if self.pose_source not in ("odometry", "truth"):
            raise InputError(f"pose_source: expected 'odometry' or 'truth', got {self.pose_source!r}")


class _CorridorRun:
    """Experiment III under way: the world and camera, odometry, the loop driver, both
    detectors' maps under both octree policies, and what is measured along the way."""

    def __init__(self, cfg: CorridorExperiment, seed: int) -> None:
        self.cfg = cfg
        ss = np.random.SeedSequence(int(seed))
        rng_odom = np.random.default_rng(ss.spawn(1)[0])
        self.noise_base, self.det_base = (int(v) for v in np.random.default_rng(ss.spawn(1)[0]).integers(0, 2**31, 2))
        self.world = build_corridor_world(cfg.scene, robot=cfg.robot, intrinsics=cfg.sensor.intrinsics)
        self.cam = KinectCamera(self.world.model, self.world.camera_id, cfg.sensor.kinect())
        self.r_from_c = robot_from_camera(cfg.scene)
        start = self.world.robot.pose(self.world.data)
        self.odom = Odometry(cfg.odometry, rng_odom, start)
        self.driver = LoopDriver(corridor_path(cfg.scene), cfg.laps, cfg.speed_mps)
        self.other = "merge" if cfg.octree.policy == "overwrite" else "overwrite"
        """The octree policy not named in the config (its maps are built too)."""
        self.policies = (cfg.octree.policy, self.other)
        self.maps = {
            (alg, pol): PlaneOctree(dataclasses.replace(cfg.octree, policy=pol)) for alg in ALGORITHMS for pol in self.policies
        }
        rate_hz = self.cam.cfg.rate_hz
        self.frame_dt = 1.0 / rate_hz
        """The world is stepped one camera frame at a time."""
        self.n_sub = max(1, round(self.frame_dt / self.world.config.timestep_s))
        self.every = max(1, round(rate_hz / cfg.map_rate_hz))
        self.acc = SparseAccumulator(cfg.detectors.hough)
        self.stats: dict[str, dict[str, list[float]]] = {
            a: {"first": [], "per_plane": [], "frame": [], "planes": []} for a in ALGORITHMS
        }
        self.render_ms: list[float] = []
        self.truth, self.est = [start.copy()], [self.odom.pose.copy()]
        self.distance = 0.0
        self.frame = 0
        self.mapped = 0
        self.max_frames = int(4.0 * self.driver.goal_m / max(cfg.speed_mps, 1e-3) * rate_hz) + 300

    def run(self, bar, rec) -> None:
        """Drive the loop (at most ``max_frames``), mapping every ``every``-th frame."""
        while self.frame < self.max_frames:
            new = self.drive_frame()
            if new is None:
                break
            if bar is not None:
                bar.update(1)
            if rec is not None:
                rec.set_time(self.frame, self.frame * self.frame_dt)
                rec.log_pose(self.frame, new)
                rec.log_estimate(self.frame, self.odom.pose)
            if self.frame % self.every:
                continue
            self.map_frame(new, rec)
            if rec is not None and self.mapped % self.cfg.rrd_every == 0:
                for alg in ALGORITHMS:
                    rec.log_plane_map(self.maps[(alg, self.cfg.octree.policy)], alg)

    def drive_frame(self) -> np.ndarray | None:
        """Drive one camera frame along the loop; the new true pose, or None when the
        distance is driven."""
        world = self.world
        pose = world.robot.pose(world.data)
        cmd = self.driver.command(pose)
        if cmd is None:
            return None
        world.robot.command(world.data, cmd, self.frame_dt)
        world.step_frame(self.n_sub)
        new = world.robot.pose(world.data)
        self.odom.update(new)
        self.distance += float(np.hypot(*(new[:2] - pose[:2])))
        self.truth.append(new)
        self.est.append(self.odom.pose.copy())
        self.frame += 1
        return new

    def map_frame(self, true_pose: np.ndarray, rec) -> None:
        """Capture a frame, detect planes with both detectors and register them into the
        maps at the configured pose (odometry or truth)."""
        cfg = self.cfg
        t0 = time.perf_counter()
        depth = self.cam.capture(self.world.data, (self.noise_base + self.frame) % (2**31))
        self.render_ms.append((time.perf_counter() - t0) * 1e3)
        rot, w_from_sensor = detection_frame(true_pose if cfg.pose_source == "truth" else self.odom.pose, self.r_from_c)
        pts, _ = depth_to_cloud(depth, cfg.sensor.intrinsics, rot, stride=cfg.detectors.stride)
        for alg in ALGORITHMS:
            det = detect(alg, pts, cfg.detectors, self.det_base + 2 * self.frame + (alg == "hough"), self.acc)
            st = self.stats[alg]
            st["frame"].append(det.total_ms)
            st["planes"].append(len(det.planes))
            if det.planes:
                st["first"].append(det.first_plane_ms)
                st["per_plane"].append(sum(det.plane_ms) / len(det.planes))
            for pol in self.policies:
                register_planes(self.maps[(alg, pol)], det, w_from_sensor, stamp=self.frame, source=alg)
            if rec is not None:
                rec.log_detection(alg, pts, det.labels, det.planes, origin=w_from_sensor[:3, 3])
        self.mapped += 1

    def summary(self) -> tuple[dict, dict]:
        """Experiment III's metrics (odometry drift, detector times, the maps' sizes and
        their walls' error) and details."""
        cfg, other = self.cfg, self.other
        truth_a, est_a = np.array(self.truth), np.array(self.est)
        segs = np.asarray(self.world.vectormap.segments)
        metrics: dict[str, float] = {
            "frames_mapped": self.mapped,
            "distance_m": self.distance,
            "duration_s": self.frame * self.frame_dt,
            "odometry_end_error_m": float(np.hypot(*(truth_a[-1, :2] - est_a[-1, :2]))),
            "odometry_end_heading_error_deg": math.degrees(abs(wrap_angle(truth_a[-1, 2] - est_a[-1, 2]))),
            "render_ms": median(self.render_ms),
        }
        details: dict[str, Any] = {"policies": [cfg.octree.policy, other], "maps": {}}
        for alg in ALGORITHMS:
            st = self.stats[alg]
            metrics[f"{alg}_first_plane_ms"] = median(st["first"])
            metrics[f"{alg}_per_plane_ms"] = median(st["per_plane"])
            metrics[f"{alg}_frame_ms"] = median(st["frame"])
            metrics[f"{alg}_planes_per_frame"] = float(np.mean(st["planes"])) if st["planes"] else 0.0
            main, alt = self.maps[(alg, cfg.octree.policy)], self.maps[(alg, other)]
            metrics[f"{alg}_map_planes"] = main.n_leaves
            metrics[f"{alg}_map_planes_{other}"] = alt.n_leaves
            metrics[f"{alg}_map_wall_error_m"] = map_wall_error(main, segs)
            metrics[f"{alg}_map_wall_error_m_{other}"] = map_wall_error(alt, segs)
            size = main.size()
            metrics[f"{alg}_map_json_kb"] = size["json_bytes"] / 1024
            details["maps"][alg] = {cfg.octree.policy: size, other: alt.size(), f"{other}_stats": vars(alt.stats), f"{cfg.octree.policy}_stats": vars(main.stats)}
        details["hough_accumulator_mb"] = accumulator_nbytes(cfg.detectors.hough) / 1e6
        details["hough_dense_accumulator_mb"] = dense_accumulator_nbytes(dataclasses.replace(cfg.detectors.hough, equal_area=False)) / 1e6
        return metrics, details

    def log_maps(self, rec) -> None:
        """Log every finished map (the other policy's under ``<alg>_<policy>``)."""
        for (alg, pol), tree in self.maps.items():
            rec.log_plane_map(tree, alg if pol == self.cfg.octree.policy else f"{alg}_{pol}")

    def export(self, out_dir: Path) -> list[str]:
        """Write every map (JSON, PLY, GLB) and the top view; the file names."""
        cfg = self.cfg
        out_dir.mkdir(parents=True, exist_ok=True)
        files: list[str] = []
        for (alg, pol), tree in self.maps.items():
            stem = f"map_{alg}" if pol == cfg.octree.policy else f"map_{alg}_{pol}"
            for ext in (".json", ".ply", ".glb"):
                f = out_dir / f"{stem}{ext}"
                tree.save_json(f) if ext == ".json" else tree.export_mesh(f)
                files.append(f.name)
        draw_maps(
            out_dir / "map_top.png",
            {f"{alg} ({pol})": self.maps[(alg, pol)] for pol in self.policies for alg in ALGORITHMS},
            np.asarray(self.world.vectormap.segments), np.array(self.truth), np.array(self.est),
            f"{cfg.name}: plane maps at the {cfg.pose_source} pose, {self.distance:.1f} m driven",
        )
        files.append("map_top.png")
        return files


def measure_corridor(
    cfg: CorridorExperiment, seed: int, progress: bool | None = False, out_dir: Path | None = None, rec=None
) -> tuple[dict, dict, Stop, list[str]]:
    """Run Experiment III: (metrics, details, how it stopped, files written).

    ``rec`` (sim.viz.recording.Recorder) logs the corridor, the true and odometry paths, each mapped
    frame's detections and the growing plane maps (every ``rrd_every`` mapped frames).
    """
    run = _CorridorRun(cfg, seed)
    bar = progress_bar(progress, run.max_frames, cfg.name)
    if rec is not None:
        rec.log_map(run.world.vectormap, None, run.world.config.wall_height_m)
    stop = until_stopped(lambda: run.run(bar, rec), bar, run.cam.close)
    if rec is not None:
        run.log_maps(rec)
    metrics, details = run.summary()
    files = run.export(out_dir) if out_dir is not None and cfg.export else []
    return metrics, details, stop, files


def _measure(cfg: CorridorExperiment, seed: int, progress: bool | None, out_dir: Path | None, rec: Any) -> tuple[dict, dict, Stop, list[str]]:
    return measure_corridor(cfg, seed, progress, out_dir, rec)


def trial_corridor(cfg: CorridorExperiment, spec: dict) -> dict:
    """One seeded run of Experiment III (no files): its metrics."""
    return run_trial(_measure, dataclasses.replace(cfg, export=False), spec)


EXPERIMENTS = {KIND: mapping_experiment(KIND, PAPER, CorridorExperiment, _measure, trial_corridor)}
