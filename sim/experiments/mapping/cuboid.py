"""PlaneMap Experiment I as the ``mapping_cuboid`` kind (III-A, Tables I and II): a
cuboid seen from the four arm views of Table I; RANSAC and the randomized Hough
transform report the angle between the two side faces they find."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError, require_int, require_positive
from autonomy.planes import (
    PlaneDetection,
    SparseAccumulator,
    angle_between_planes_deg,
    depth_to_cloud,
)
from sim.config import to_dict
from sim.experiments.mapping.common import (
    ALGORITHMS,
    MappingExperiment,
    Stop,
    detect,
    progress_bar,
    seeds,
    until_stopped,
)
from sim.experiments.mapping.driver import mapping_experiment
from sim.scenes.cuboid import (
    TABLE_I_VIEWS,
    ArmView,
    CuboidScene,
    build_cuboid_rig,
    visible_side_faces,
)

KIND = "mapping_cuboid"

#: Table II: the angle between the two detected faces of the cuboid, views 1-4.
PAPER: dict[str, float] = {
    "ransac_angle_view1_deg": 87.7,
    "ransac_angle_view2_deg": 88.3,
    "ransac_angle_view3_deg": 87.3,
    "ransac_angle_view4_deg": 87.1,
    "hough_angle_view1_deg": 87.1,
    "hough_angle_view2_deg": 87.4,
    "hough_angle_view3_deg": 87.2,
    "hough_angle_view4_deg": 86.3,
}


@dataclass(frozen=True)
class CuboidExperiment(MappingExperiment):
    """Experiment I: the angle between two faces of a cuboid (III-A, Tables I and II)."""

    name: str = KIND
    """Scenario name."""
    views: tuple[ArmView, ...] = TABLE_I_VIEWS
    """Arm joint angles of each view (Table I)."""
    frames_per_view: int = 10
    """Noisy frames per view (one detection each; the angle is their mean)."""
    scene: CuboidScene = field(default_factory=CuboidScene)
    """Cuboid and arm geometry."""
    match_angle_deg: float = 15.0
    """A detected plane is a face if its normal is within this angle of the face's ..."""
    match_distance_m: float = 0.05
    """... and its rho within this distance of the face's."""

    def __post_init__(self) -> None:
        if not self.views:
            raise InputError("views: expected at least one view")
        require_int(self, "", "frames_per_view")
        require_positive(self, "", "match_angle_deg", "match_distance_m")


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
    cfg: CuboidExperiment, vi: int, draws: list[int], acc: SparseAccumulator, tally: _CuboidTally, rec: Any, bar: Any
) -> None:
    """Capture the noisy frames of view ``vi`` and measure the face angle in each."""
    intr, n_frames = cfg.sensor.intrinsics, cfg.frames_per_view
    rig = build_cuboid_rig(cfg.scene, cfg.views[vi], intr)
    cam = rig.camera(cfg.sensor.kinect())
    rot, pos = rig.world_from_camera[:3, :3], rig.world_from_camera[:3, 3]
    faces = _cuboid_faces(cfg, cfg.views[vi], pos)
    try:
        for f in range(n_frames):
            i = vi * n_frames + f
            depth = cam.capture(rig.data, draws[2 * i] % (2**31))
            pts, _ = depth_to_cloud(depth, intr, rot, stride=cfg.detectors.stride)
            if rec is not None:
                rec.set_time(i, float(i))
            for alg in ALGORITHMS:
                det = detect(alg, pts, cfg.detectors, draws[2 * i + 1], acc)
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
    draws = seeds(seed, 2 * cfg.frames_per_view * len(cfg.views))
    tally = _CuboidTally(len(cfg.views))
    bar = progress_bar(progress, cfg.frames_per_view * len(cfg.views), cfg.name)
    acc = SparseAccumulator(cfg.detectors.hough)

    def work() -> None:
        for vi in range(len(cfg.views)):
            _cuboid_view(cfg, vi, draws, acc, tally, rec, bar)

    stop = until_stopped(work, bar)
    return (*_cuboid_summary(cfg, tally), stop)


def _measure(cfg: CuboidExperiment, seed: int, progress: bool | None, out_dir: Path | None, rec: Any) -> tuple[dict, dict, Stop, list[str]]:
    return (*measure_cuboid(cfg, seed, progress, rec), [])


EXPERIMENTS = {KIND: mapping_experiment(KIND, PAPER, CuboidExperiment, _measure)}
