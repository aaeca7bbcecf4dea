"""PlaneMap's three experiments as scenario kinds: ``mapping_cuboid``, ``mapping_wall``, ``mapping_corridor``.

- I, cuboid angle (III-A, Table II): a cuboid seen from the four arm views of Table I;
  both detectors report the angle between the two side faces they find.
- II, wall distance (III-B, Table III): the camera facing a flat wall at 1.06 m and
  1.56 m; the standard deviation of the error in rho of the wall's points.
- III, corridor mapping (III-C, IV-C): the robot drives a corridor loop with the camera
  looking right; planes from both detectors are registered into octree maps at the
  odometry pose (no loop closure), exported and drawn; time to the first plane, per
  plane, and the maps' sizes.

Every run writes ``report.json`` with ``metrics`` (ours) and ``paper`` (PlaneMap's
figures under the same names). A run stopped by Ctrl-C or by an error keeps the metrics
of the frames it finished; an error adds an ``error`` block and the traceback in
``crash.txt``, and the run raises :class:`sim.experiments.kinds.RunCrashed`. A sweep
trial is one seeded noise draw of the whole experiment; the summary gives each metric's mean, std, min and max over trials.

Point clouds are handed to the detectors in a sensor-centred frame with z up (the
camera's rotation to the world applied, its position not), so rho is the distance from
the camera and the Hough accumulator's pole points at the ceiling.
"""

from __future__ import annotations

import dataclasses
import math
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError, require_int, require_positive
from autonomy.common.geometry import point_segment_distance, wrap_angle
from autonomy.perception.camera import CameraIntrinsics
from autonomy.planes import (
    HoughConfig,
    OctreeConfig,
    PlaneDetection,
    PlaneOctree,
    RansacConfig,
    SparseAccumulator,
    accumulator_nbytes,
    angle_between_planes_deg,
    dense_accumulator_nbytes,
    depth_to_cloud,
    detection_frame,
    hough_planes,
    ransac_planes,
    register_planes,
)
from sim.config import to_dict
from sim.experiments.kinds import Experiment, crash_block, stopped, write_crash
from sim.experiments.report_file import write_json
from sim.scenes.corridor import CorridorScene
from sim.scenes.cuboid import TABLE_I_VIEWS, ArmView, CuboidScene
from sim.scenes.wall import WallScene
from sim.simulator.kinect_noise import KinectNoiseConfig
from sim.simulator.robot import OdometryConfig, RobotConfig

REPORT_VERSION = 1
ALGORITHMS = ("ransac", "hough")

#: PlaneMap's figures, under our metric names.
PAPER: dict[str, dict[str, float]] = {
    # Table II: angle between the two detected faces of the cuboid, views 1-4.
    "mapping_cuboid": {
        "ransac_angle_view1_deg": 87.7,
        "ransac_angle_view2_deg": 88.3,
        "ransac_angle_view3_deg": 87.3,
        "ransac_angle_view4_deg": 87.1,
        "hough_angle_view1_deg": 87.1,
        "hough_angle_view2_deg": 87.4,
        "hough_angle_view3_deg": 87.2,
        "hough_angle_view4_deg": 86.3,
    },
    # Table III: standard deviation of the measurement error in rho at 106 and 156 cm.
    "mapping_wall": {
        "ransac_rho_std_mm_106cm": 3.9,
        "ransac_rho_std_mm_156cm": 8.8,
        "hough_rho_std_mm_106cm": 2.5,
        "hough_rho_std_mm_156cm": 7.4,
    },
    # IV-C: RANSAC 50 ms to the first plane, Hough 170 ms a plane (Core 2 Duo, 2.8 GHz).
    "mapping_corridor": {"ransac_first_plane_ms": 50.0, "hough_per_plane_ms": 170.0},
}


# -- configuration ----------------------------------------------------------------------


@dataclass(frozen=True)
class SensorConfig:
    """The depth camera of a rig: intrinsics, noise model and rendering backend."""

    intrinsics: CameraIntrinsics = field(default_factory=CameraIntrinsics)
    """Pinhole intrinsics (640 x 480, f = 580 px)."""
    noise: KinectNoiseConfig = field(default_factory=KinectNoiseConfig)
    """Kinect noise model (every term switchable)."""
    backend: str = "auto"
    """auto, gl or raycast (see sim.simulator.kinect)."""

    def kinect(self):
        from sim.simulator.kinect import KinectConfig

        return KinectConfig(intrinsics=self.intrinsics, noise=self.noise, backend=self.backend)


@dataclass(frozen=True)
class DetectorsConfig:
    """Both plane detectors and how their point clouds are made."""

    ransac: RansacConfig = field(default_factory=RansacConfig)
    """Multi-plane RANSAC (Section II-B2)."""
    hough: HoughConfig = field(default_factory=HoughConfig)
    """Randomized Hough transform (Section II-B1)."""
    stride: int = 1
    """Use every stride-th pixel in both directions (1 = the whole 640 x 480 frame)."""

    def __post_init__(self) -> None:
        require_int(self, "detectors.", "stride")


@dataclass(frozen=True)
class CuboidExperiment:
    """Experiment I: the angle between two faces of a cuboid (III-A, Tables I and II)."""

    name: str = "mapping_cuboid"
    """Scenario name."""
    description: str = ""
    """One line on what it shows."""
    seed: int = 0
    """Seed of the noise draws and the detectors."""
    base_dir: str = "."
    """Directory of the scenario file (set by the loader)."""
    views: tuple[ArmView, ...] = TABLE_I_VIEWS
    """Arm joint angles of each view (Table I)."""
    frames_per_view: int = 10
    """Noisy frames per view (one detection each; the angle is their mean)."""
    scene: CuboidScene = field(default_factory=CuboidScene)
    """Cuboid and arm geometry."""
    sensor: SensorConfig = field(default_factory=SensorConfig)
    """The Kinect."""
    detectors: DetectorsConfig = field(default_factory=DetectorsConfig)
    """RANSAC and Hough parameters."""
    match_angle_deg: float = 15.0
    """A detected plane is a face if its normal is within this angle of the face's ..."""
    match_distance_m: float = 0.05
    """... and its rho within this distance of the face's."""

    def __post_init__(self) -> None:
        if not self.views:
            raise InputError("views: expected at least one view")
        require_int(self, "", "frames_per_view")
        require_positive(self, "", "match_angle_deg", "match_distance_m")


@dataclass(frozen=True)
class WallExperiment:
    """Experiment II: the error in rho of a flat wall's points (III-B, Table III)."""

    name: str = "mapping_wall"
    """Scenario name."""
    description: str = ""
    """One line on what it shows."""
    seed: int = 0
    """Seed of the noise draws and the detectors."""
    base_dir: str = "."
    """Directory of the scenario file (set by the loader)."""
    distances_m: tuple[float, ...] = (1.06, 1.56)
    """Camera-to-wall distances (106 cm, then 50 cm further)."""
    frames: int = 20
    """Noisy frames per distance."""
    gate_m: float = 0.05
    """Points within this distance of the detected wall count as the wall's measurements."""
    scene: WallScene = field(default_factory=WallScene)
    """Wall rig geometry."""
    sensor: SensorConfig = field(default_factory=SensorConfig)
    """The Kinect."""
    detectors: DetectorsConfig = field(default_factory=DetectorsConfig)
    """RANSAC and Hough parameters."""

    def __post_init__(self) -> None:
        if not self.distances_m or not all(d > 0 for d in self.distances_m):
            raise InputError(f"distances_m: expected positive distances, got {self.distances_m!r}")
        require_int(self, "", "frames")
        require_positive(self, "", "gate_m")


@dataclass(frozen=True)
class CorridorExperiment:
    """Experiment III: octree plane maps of a corridor loop from odometry (III-C, IV-C)."""

    name: str = "mapping_corridor"
    """Scenario name."""
    description: str = ""
    """One line on what it shows."""
    seed: int = 0
    """Seed of odometry noise, sensor noise and the detectors."""
    base_dir: str = "."
    """Directory of the scenario file (set by the loader)."""
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
    sensor: SensorConfig = field(default_factory=SensorConfig)
    """The Kinect."""
    detectors: DetectorsConfig = field(default_factory=DetectorsConfig)
    """RANSAC and Hough parameters."""
    export: bool = True
    """Write the maps (JSON, PLY, GLB) and the top-view PNG."""
    rrd_every: int = 5
    """With ``--rrd``: log the growing plane maps every this many mapped frames (1 s at 5 Hz)."""

    def __post_init__(self) -> None:
        require_positive(self, "", "laps", "speed_mps", "map_rate_hz")
        require_int(self, "", "rrd_every")
        if self.pose_source not in ("odometry", "truth"):
            raise InputError(f"pose_source: expected 'odometry' or 'truth', got {self.pose_source!r}")


# -- shared helpers ---------------------------------------------------------------------


def _detect(alg: str, pts: np.ndarray, det: DetectorsConfig, seed: int, acc: SparseAccumulator | None = None) -> PlaneDetection:
    if alg == "ransac":
        return ransac_planes(pts, det.ransac, seed)
    return hough_planes(pts, det.hough, seed, acc)


def _seeds(seed: int, n: int) -> list[int]:
    return [int(s) for s in np.random.SeedSequence(int(seed)).generate_state(n, dtype=np.uint32)]


def _finite(v: float) -> float | None:
    return round(float(v), 4) if v is not None and math.isfinite(float(v)) else None


def _median(xs: list[float]) -> float:
    return float(np.median(xs)) if xs else float("nan")


@dataclass(frozen=True)
class Stop:
    """How a measurement's loop ended early: Ctrl-C, or the error that stopped it."""

    interrupted: bool = False
    error: Exception | None = None

    @property
    def early(self) -> bool:
        return self.interrupted or self.error is not None


def _until_stopped(work: Callable[[], None], bar, *close: Callable[[], None]) -> Stop:
    """Run ``work()``; whether Ctrl-C or an error stopped it (what it measured so far is
    kept either way). The ``close`` callables and the progress bar are closed either way."""
    try:
        work()
    except KeyboardInterrupt:
        return Stop(interrupted=True)
    except Exception as exc:  # a bug in the loop: the frames before it are reported
        return Stop(error=exc)
    finally:
        for c in close:
            c()
        if bar is not None:
            bar.close()
    return Stop()


def _progress(progress: bool | None, total: int, desc: str):
    show = progress if progress is not None else sys.stderr.isatty()
    if not show:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame", leave=False)


def _write_report(out_dir: Path, report: dict) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "report.json", report)


def _report(kind: str, cfg: Any, seed: int, metrics: dict, details: dict, interrupted: bool, files: list[str], wall_s: float) -> dict:
    return {
        "version": REPORT_VERSION,
        "scenario": cfg.name,
        "kind": kind,
        "seed": seed,
        "interrupted": interrupted,
        "metrics": {k: _finite(v) for k, v in metrics.items()},
        "paper": PAPER[kind],
        "details": details,
        "files": files,
        "wall_time_s": round(wall_s, 2),
        "machine": f"Python {platform.python_version()}, {os.cpu_count()} cores, {platform.processor() or platform.machine()}",
        "config": to_dict(cfg),
    }


# -- Experiment I: cuboid angle ------------------------------------------------------------


def _match_face(det: PlaneDetection, n_true: np.ndarray, rho_true: float, max_angle_deg: float, max_dist_m: float) -> int:
    """Index of the detected plane best matching a face (normal, rho), or -1."""
    best, best_ang = -1, max_angle_deg
    for k, p in enumerate(det.planes):
        ang = math.degrees(math.acos(min(1.0, float(p.normal @ n_true))))
        if ang <= best_ang and abs(p.rho - rho_true) <= max_dist_m:
            best, best_ang = k, ang
    return best


def _cuboid_faces(cfg: CuboidExperiment, view: ArmView, pos: np.ndarray) -> list[tuple[np.ndarray, float]]:
    """The two visible side faces as (normal, rho) in the sensor-centred frame, normals
    pointing away from the camera."""
    from sim.scenes.cuboid import visible_side_faces

    faces = []
    for n_out, d in visible_side_faces(cfg.scene, view):
        n, rho = -n_out, -(d - float(n_out @ pos))
        faces.append((n, rho) if rho >= 0 else (-n, -rho))
    return faces


def _face_angle(cfg: CuboidExperiment, det: PlaneDetection, faces: list[tuple[np.ndarray, float]]) -> float | None:
    """Angle between the planes detected for the two faces; None unless both are found
    as two different planes."""
    k1 = _match_face(det, *faces[0], cfg.match_angle_deg, cfg.match_distance_m)
    k2 = _match_face(det, *faces[1], cfg.match_angle_deg, cfg.match_distance_m)
    if k1 >= 0 and k2 >= 0 and k1 != k2:
        return angle_between_planes_deg(det.planes[k1].normal, det.planes[k2].normal)
    return None


@dataclass
class _CuboidTally:
    """What Experiment I measures, per detector: face angles per view, frame times, planes found."""

    n_views: int
    angles: dict[str, list[list[float]]] = field(init=False)
    times: dict[str, list[float]] = field(init=False)
    planes_found: dict[str, list[int]] = field(init=False)

    def __post_init__(self) -> None:
        self.angles = {a: [[] for _ in range(self.n_views)] for a in ALGORITHMS}
        self.times = {a: [] for a in ALGORITHMS}
        self.planes_found = {a: [] for a in ALGORITHMS}

    def add(self, alg: str, view: int, det: PlaneDetection, angle: float | None) -> None:
        self.times[alg].append(det.total_ms)
        self.planes_found[alg].append(len(det.planes))
        if angle is not None:
            self.angles[alg][view].append(angle)


def _cuboid_view(
    cfg: CuboidExperiment, vi: int, seeds: list[int], acc: SparseAccumulator, tally: _CuboidTally, rec, bar
) -> None:
    """Capture the noisy frames of view ``vi`` and measure the face angle in each."""
    from sim.scenes.cuboid import build_cuboid_rig

    intr, n_frames = cfg.sensor.intrinsics, cfg.frames_per_view
    rig = build_cuboid_rig(cfg.scene, cfg.views[vi], intr)
    cam = rig.camera(cfg.sensor.kinect())
    rot, pos = rig.world_from_camera[:3, :3], rig.world_from_camera[:3, 3]
    faces = _cuboid_faces(cfg, cfg.views[vi], pos)
    try:
        for f in range(n_frames):
            i = vi * n_frames + f
            depth = cam.capture(rig.data, seeds[2 * i] % (2**31))
            pts, _ = depth_to_cloud(depth, intr, rot, stride=cfg.detectors.stride)
            if rec is not None:
                rec.set_time(i, float(i))
            for alg in ALGORITHMS:
                det = _detect(alg, pts, cfg.detectors, seeds[2 * i + 1], acc)
                if rec is not None:
                    rec.log_detection(alg, pts, det.labels, det.planes, origin=pos)
                tally.add(alg, vi, det, _face_angle(cfg, det, faces))
            if bar is not None:
                bar.update(1)
    finally:
        cam.close()


def _cuboid_summary(cfg: CuboidExperiment, tally: _CuboidTally) -> tuple[dict, dict]:
    """Experiment I's metrics (Table II's angles, faces found, errors, frame time) and details."""
    metrics: dict[str, float] = {}
    details: dict[str, Any] = {"views": [to_dict(v) for v in cfg.views], "per_view": {}}
    for alg in ALGORITHMS:
        errs = []
        found = 0
        for vi in range(len(cfg.views)):
            a = tally.angles[alg][vi]
            metrics[f"{alg}_angle_view{vi + 1}_deg"] = float(np.mean(a)) if a else float("nan")
            errs += [abs(x - 90.0) for x in a]
            found += len(a)
            details["per_view"][f"{alg}_view{vi + 1}"] = {
                "angles_deg": [round(x, 3) for x in a],
                "std_deg": round(float(np.std(a)), 4) if a else None,
            }
        times, planes_found = tally.times[alg], tally.planes_found[alg]
        metrics[f"{alg}_faces_found_fraction"] = found / (cfg.frames_per_view * len(cfg.views))
        metrics[f"{alg}_mean_abs_error_deg"] = float(np.mean(errs)) if errs else float("nan")
        metrics[f"{alg}_frame_ms"] = float(np.median(times)) if times else float("nan")
        details[f"{alg}_planes_per_frame"] = float(np.mean(planes_found)) if planes_found else 0.0
    return metrics, details


def measure_cuboid(cfg: CuboidExperiment, seed: int, progress: bool | None = False, rec=None) -> tuple[dict, dict, Stop]:
    """Run Experiment I: (metrics, details, how it stopped); ``rec`` (sim.viz.recording.Recorder) logs each frame's detections."""
    seeds = _seeds(seed, 2 * cfg.frames_per_view * len(cfg.views))
    tally = _CuboidTally(len(cfg.views))
    bar = _progress(progress, cfg.frames_per_view * len(cfg.views), cfg.name)
    acc = SparseAccumulator(cfg.detectors.hough)

    def work() -> None:
        for vi in range(len(cfg.views)):
            _cuboid_view(cfg, vi, seeds, acc, tally, rec, bar)

    stop = _until_stopped(work, bar)
    return (*_cuboid_summary(cfg, tally), stop)


# -- Experiment II: wall distance ------------------------------------------------------------


def _wall_plane(det: PlaneDetection, dist: float, gate_m: float) -> int:
    """Index of the detected plane taken for the wall (normal within 10 degrees of the
    wall's, rho within ``gate_m`` of its distance, the most points), or -1."""
    n_true = np.array([1.0, 0.0, 0.0])
    best = -1
    for j, p in enumerate(det.planes):
        if p.normal @ n_true > math.cos(math.radians(10)) and abs(p.rho - dist) < gate_m:
            if best < 0 or p.n_points > det.planes[best].n_points:
                best = j
    return best


@dataclass
class _WallTally:
    """One detector's measurements of the wall at one distance: the residuals in rho of the
    points near the detected wall and of its inliers, and each frame's error in rho."""

    resid: list[np.ndarray] = field(default_factory=list)
    inlier_resid: list[np.ndarray] = field(default_factory=list)
    rho_err: list[float] = field(default_factory=list)

    def add(self, det: PlaneDetection, best: int, pts: np.ndarray, dist: float, gate_m: float) -> None:
        p = det.planes[best]
        self.rho_err.append(p.rho - dist)
        r = pts @ p.normal.astype(np.float32) - np.float32(p.rho)
        self.resid.append(r[np.abs(r) < gate_m])
        self.inlier_resid.append(r[det.labels == best])

    def summarize(self, alg: str, tag: str, dist: float, metrics: dict, details: dict) -> None:
        """Add Table III's standard deviation of the error in rho (and the bias) under ``tag``."""
        rr = np.concatenate(self.resid) if self.resid else np.zeros(0)
        ri = np.concatenate(self.inlier_resid) if self.inlier_resid else np.zeros(0)
        e = np.array(self.rho_err)
        metrics[f"{alg}_rho_std_mm_{tag}"] = float(np.std(rr)) * 1e3 if len(rr) else float("nan")
        metrics[f"{alg}_inlier_rho_std_mm_{tag}"] = float(np.std(ri)) * 1e3 if len(ri) else float("nan")
        metrics[f"{alg}_frame_rho_std_mm_{tag}"] = float(np.std(e)) * 1e3 if len(e) else float("nan")
        metrics[f"{alg}_rho_bias_mm_{tag}"] = float(np.mean(e)) * 1e3 if len(e) else float("nan")
        details[f"{alg}_{tag}"] = {
            "frames_with_wall": len(e),
            "points_per_frame": round(len(rr) / max(len(e), 1)),
            "rho_m": [round(dist + x, 6) for x in e],
        }


def _wall_distance(
    cfg: WallExperiment, di: int, seeds: list[int], acc: SparseAccumulator, rec, bar
) -> dict[str, _WallTally]:
    """Capture the noisy frames at distance ``di`` and measure the wall in each."""
    from sim.scenes.wall import build_wall_rig

    intr, dist = cfg.sensor.intrinsics, cfg.distances_m[di]
    rig = build_wall_rig(dist, cfg.scene, intr)
    cam = rig.camera(cfg.sensor.kinect())
    rot = rig.world_from_camera[:3, :3]
    tally = {a: _WallTally() for a in ALGORITHMS}
    try:
        for f in range(cfg.frames):
            i = di * cfg.frames + f
            depth = cam.capture(rig.data, seeds[2 * i] % (2**31))
            pts, _ = depth_to_cloud(depth, intr, rot, stride=cfg.detectors.stride)
            if rec is not None:
                rec.set_time(i, float(i))
            for alg in ALGORITHMS:
                det = _detect(alg, pts, cfg.detectors, seeds[2 * i + 1], acc)
                if rec is not None:
                    rec.log_detection(alg, pts, det.labels, det.planes, origin=rig.world_from_camera[:3, 3])
                best = _wall_plane(det, dist, cfg.gate_m)
                if best >= 0:
                    tally[alg].add(det, best, pts, dist, cfg.gate_m)
            if bar is not None:
                bar.update(1)
    finally:
        cam.close()
    return tally


def measure_wall(cfg: WallExperiment, seed: int, progress: bool | None = False, rec=None) -> tuple[dict, dict, Stop]:
    """Run Experiment II: (metrics, details, how it stopped); ``rec`` (sim.viz.recording.Recorder) logs each frame's detections."""
    seeds = _seeds(seed, 2 * cfg.frames * len(cfg.distances_m))
    bar = _progress(progress, cfg.frames * len(cfg.distances_m), cfg.name)
    metrics: dict[str, float] = {}
    details: dict[str, Any] = {}
    acc = SparseAccumulator(cfg.detectors.hough)

    def work() -> None:
        for di, dist in enumerate(cfg.distances_m):
            tally = _wall_distance(cfg, di, seeds, acc, rec, bar)
            for alg in ALGORITHMS:
                tally[alg].summarize(alg, f"{round(dist * 100)}cm", dist, metrics, details)

    stop = _until_stopped(work, bar)
    return metrics, details, stop


# -- Experiment III: corridor mapping ------------------------------------------------------------


class LoopDriver:
    """Carrot follower along the closed corridor path (ground truth: the robot drives, the map uses odometry)."""

    def __init__(self, path: np.ndarray, laps: float, speed: float, lookahead: float = 0.6) -> None:
        seg = np.diff(path, axis=0)
        self.lengths = np.hypot(seg[:, 0], seg[:, 1])
        self.lap_m = float(self.lengths.sum())
        self.path = path
        self.cum = np.concatenate([[0.0], np.cumsum(self.lengths)])
        self.goal_m = laps * self.lap_m
        self.speed = speed
        self.lookahead = lookahead
        self.s = 0.0

    def point(self, s: float) -> tuple[np.ndarray, float]:
        s = s % self.lap_m
        k = min(int(np.searchsorted(self.cum, s, side="right")) - 1, len(self.lengths) - 1)
        d = (self.path[k + 1] - self.path[k]) / self.lengths[k]
        return self.path[k] + d * (s - self.cum[k]), math.atan2(d[1], d[0])

    def command(self, pose: np.ndarray) -> np.ndarray | None:
        """Body velocity (vx, vy, w), or None when the distance is driven."""
        # Progress: the nearest path point within a window ahead of the last one.
        cand = self.s + np.linspace(-0.2, 1.0, 61)
        pts = np.array([self.point(c)[0] for c in cand])
        self.s = max(self.s, float(cand[int(np.argmin(np.hypot(*(pts - pose[:2]).T)))]))
        if self.s >= self.goal_m:
            return None
        target, _ = self.point(self.s + self.lookahead)
        _, heading = self.point(self.s + 0.3)
        d = target - pose[:2]
        v = d / max(float(np.hypot(*d)), 1e-9) * self.speed
        err = wrap_angle(heading - pose[2])
        w = max(-1.0, min(1.0, 2.0 * err))
        c, s = math.cos(pose[2]), math.sin(pose[2])
        return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], w])


def map_wall_error(tree: PlaneOctree, segs: np.ndarray) -> float:
    """Median distance (m) of the map's wall planes (normal within 30 degrees of horizontal) to the nearest true wall."""
    d = [
        float(np.min(point_segment_distance(np.asarray(p.centroid[:2]), segs)))
        for p in tree.planes()
        if abs(p.normal[2]) < math.sin(math.radians(30.0))
    ]
    return float(np.median(d)) if d else float("nan")


def draw_maps(path: Path, maps: dict[str, PlaneOctree], segs: np.ndarray, truth: np.ndarray, odom: np.ndarray, title: str) -> Path:
    """Top view PNG: true walls, trajectories and each map's plane patches (one panel a map)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.figure import Figure

    cols = min(len(maps), 2)
    rows = -(-len(maps) // cols)
    fig = Figure(figsize=(6.5 * cols, 5.0 * rows))
    FigureCanvasAgg(fig)
    for k, (name, tree) in enumerate(maps.items()):
        ax = fig.add_subplot(rows, cols, k + 1)
        ax.add_collection(LineCollection(segs.reshape(-1, 2, 2), colors="#bbbbbb", linewidths=2.0, label="true walls"))
        lines, colors, polys = [], [], []
        for lf in tree.leaves():
            p = lf.entry.plane
            if len(p.hull) < 2:
                continue
            if abs(p.normal[2]) < 0.5:  # a wall: its footprint, the hull's extent along the wall
                t = np.array([-p.normal[1], p.normal[0]])
                t /= np.linalg.norm(t)
                s = p.hull[:, :2] @ t
                base = p.centroid[:2] - (p.centroid[:2] @ t) * t
                lines.append([base + s.min() * t, base + s.max() * t])
                colors.append("#08306b")
            else:
                polys.append(p.hull[:, :2])
        if polys:
            ax.add_collection(PolyCollection(polys, facecolors="#9ecae1", edgecolors="none", alpha=0.4))
        if lines:
            ax.add_collection(LineCollection(lines, colors=colors, linewidths=1.2, label="wall planes"))
        ax.plot(truth[:, 0], truth[:, 1], "-", color="#2ca02c", lw=0.8, label="true path")
        ax.plot(odom[:, 0], odom[:, 1], "--", color="#d62728", lw=0.8, label="odometry")
        ax.set_aspect("equal")
        ax.autoscale()
        ax.set_title(f"{name}: {tree.n_leaves} planes")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.legend(loc="upper right", fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    return path


class _CorridorRun:
    """Experiment III under way: the world and camera, odometry, the loop driver, both
    detectors' maps under both octree policies, and what is measured along the way."""

    def __init__(self, cfg: CorridorExperiment, seed: int) -> None:
        from sim.scenes.corridor import build_corridor_world, corridor_path, robot_from_camera
        from sim.simulator.kinect import KinectCamera
        from sim.simulator.robot import Odometry

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
            det = _detect(alg, pts, cfg.detectors, self.det_base + 2 * self.frame + (alg == "hough"), self.acc)
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
            "render_ms": _median(self.render_ms),
        }
        details: dict[str, Any] = {"policies": [cfg.octree.policy, other], "maps": {}}
        for alg in ALGORITHMS:
            st = self.stats[alg]
            metrics[f"{alg}_first_plane_ms"] = _median(st["first"])
            metrics[f"{alg}_per_plane_ms"] = _median(st["per_plane"])
            metrics[f"{alg}_frame_ms"] = _median(st["frame"])
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
    bar = _progress(progress, run.max_frames, cfg.name)
    if rec is not None:
        rec.log_map(run.world.vectormap, None, run.world.config.wall_height_m)
    stop = _until_stopped(lambda: run.run(bar, rec), bar, run.cam.close)
    if rec is not None:
        run.log_maps(rec)
    metrics, details = run.summary()
    files = run.export(out_dir) if out_dir is not None and cfg.export else []
    return metrics, details, stop, files


# -- run / sweep entry points ----------------------------------------------------------


def _measure(kind: str, cfg: Any, seed: int, progress: bool | None, out: Path | None, rec=None) -> tuple[dict, dict, Stop, list[str]]:
    if kind == "mapping_cuboid":
        return (*measure_cuboid(cfg, seed, progress, rec), [])
    if kind == "mapping_wall":
        return (*measure_wall(cfg, seed, progress, rec), [])
    return measure_corridor(cfg, seed, progress, out, rec)


def _run(kind: str, cfg: Any, out_dir: str | Path, seed: int | None, rrd, spawn: bool, progress: bool | None) -> dict:
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out}: cannot create the output directory: {exc.strerror or exc}") from None
    seed = cfg.seed if seed is None else int(seed)
    t0 = time.perf_counter()
    rec = None
    if rrd or spawn:
        from sim.viz.recording import Recorder

        rate_hz = cfg.sensor.kinect().rate_hz
        every = max(1, round(rate_hz / getattr(cfg, "map_rate_hz", rate_hz)))
        rec = Recorder(rrd, spawn=spawn, every=every, recording_id=f"{cfg.name}-{seed}")
    try:
        metrics, details, stop, files = _measure(kind, cfg, seed, progress, out, rec)
    except Exception as exc:  # the summary of what the loop left failed: the error is kept
        metrics, details, stop, files = {}, {}, Stop(error=exc), []
    finally:
        if rec is not None:
            rec.close()
    if rrd:
        rp = Path(rrd)
        files.append(rp.name if rp.parent.resolve() == out.resolve() else str(rp))
    report = _report(kind, cfg, seed, metrics, details, stop.early, files, time.perf_counter() - t0)
    err = stop.error
    if err is not None:
        report["error"] = crash_block(err)
        write_crash(out, err)
    _write_report(out, report)
    if err is not None:
        raise stopped(err, "the run stopped", out / "report.json") from None
    return report


def run_cuboid(cfg: CuboidExperiment, out_dir: str | Path, *, seed: int | None = None, rrd=None, spawn: bool = False, progress: bool | None = None) -> dict:
    """Experiment I: writes out_dir/report.json; returns the report."""
    return _run("mapping_cuboid", cfg, out_dir, seed, rrd, spawn, progress)


def run_wall(cfg: WallExperiment, out_dir: str | Path, *, seed: int | None = None, rrd=None, spawn: bool = False, progress: bool | None = None) -> dict:
    """Experiment II: writes out_dir/report.json; returns the report."""
    return _run("mapping_wall", cfg, out_dir, seed, rrd, spawn, progress)


def run_corridor(cfg: CorridorExperiment, out_dir: str | Path, *, seed: int | None = None, rrd=None, spawn: bool = False, progress: bool | None = None) -> dict:
    """Experiment III: writes report.json, the maps (JSON, PLY, GLB) and map_top.png; returns the report."""
    return _run("mapping_corridor", cfg, out_dir, seed, rrd, spawn, progress)


def trials(cfg: Any, n: int, seed: int) -> list[dict]:
    """``n`` trials, each one seeded noise draw of the whole experiment."""
    return [{"id": f"trial-{i:04d}", "seed": s} for i, s in enumerate(_seeds(seed, n))]


def _trial(kind: str, cfg: Any, spec: dict) -> dict:
    s = int(spec["seed"])
    if kind == "mapping_corridor":
        cfg = dataclasses.replace(cfg, export=False)
    metrics, _, stop, _ = _measure(kind, cfg, s, False, None)
    if stop.error is not None:
        raise stop.error
    if stop.interrupted:
        raise KeyboardInterrupt
    return {"seed": s, "metrics": {k: _finite(v) for k, v in metrics.items()}}


def trial_cuboid(cfg: CuboidExperiment, spec: dict) -> dict:
    """One seeded draw of Experiment I: its metrics."""
    return _trial("mapping_cuboid", cfg, spec)


def trial_wall(cfg: WallExperiment, spec: dict) -> dict:
    """One seeded draw of Experiment II: its metrics."""
    return _trial("mapping_wall", cfg, spec)


def trial_corridor(cfg: CorridorExperiment, spec: dict) -> dict:
    """One seeded run of Experiment III (no files): its metrics."""
    return _trial("mapping_corridor", cfg, spec)


def _summarize(kind: str, cfg: Any, results: list[dict], out_dir: Path) -> dict:
    out = Path(out_dir)
    keys = sorted({k for r in results for k in r["metrics"]})
    per: dict[str, dict[str, float | None]] = {}
    metrics: dict[str, float | None] = {"trials": len(results)}
    for k in keys:
        v = np.array([r["metrics"][k] for r in results if r["metrics"].get(k) is not None], dtype=np.float64)
        if not len(v):
            per[k] = {"mean": None, "std": None, "min": None, "max": None, "n": 0}
            metrics[k] = None
            continue
        per[k] = {"mean": _finite(v.mean()), "std": _finite(v.std()), "min": _finite(v.min()), "max": _finite(v.max()), "n": len(v)}
        metrics[k] = _finite(v.mean())
    report = {
        "version": REPORT_VERSION,
        "scenario": cfg.name,
        "kind": kind,
        "trials": len(results),
        "interrupted": False,
        "metrics": metrics,
        "per_metric": per,
        "paper": PAPER[kind],
        "seeds": [r["seed"] for r in results],
        "config": to_dict(cfg),
    }
    _write_report(out, report)
    return report


def summarize_cuboid(cfg: CuboidExperiment, results: list[dict], out_dir: Path) -> dict:
    """Mean, std, min and max of every Experiment I metric over trials; writes report.json."""
    return _summarize("mapping_cuboid", cfg, results, out_dir)


def summarize_wall(cfg: WallExperiment, results: list[dict], out_dir: Path) -> dict:
    """Mean, std, min and max of every Experiment II metric over trials; writes report.json."""
    return _summarize("mapping_wall", cfg, results, out_dir)


def summarize_corridor(cfg: CorridorExperiment, results: list[dict], out_dir: Path) -> dict:
    """Mean, std, min and max of every Experiment III metric over trials; writes report.json."""
    return _summarize("mapping_corridor", cfg, results, out_dir)


EXPERIMENTS = {
    "mapping_cuboid": Experiment("mapping_cuboid", CuboidExperiment, run_cuboid, trials, trial_cuboid, summarize_cuboid),
    "mapping_wall": Experiment("mapping_wall", WallExperiment, run_wall, trials, trial_wall, summarize_wall),
    "mapping_corridor": Experiment("mapping_corridor", CorridorExperiment, run_corridor, trials, trial_corridor, summarize_corridor),
}
