"""PlaneMap Experiment II as the ``mapping_wall`` kind (III-B, Table III): the camera
facing a flat wall at 1.06 m and 1.56 m; the standard deviation of the error in rho of
the wall's points, for RANSAC and the randomized Hough transform."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError, require_int, require_positive
from autonomy.planes import PlaneDetection, SparseAccumulator, depth_to_cloud
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
from sim.scenes.wall import WallScene, build_wall_rig

KIND = "mapping_wall"

#: Table III: the standard deviation of the measurement error in rho at 106 and 156 cm.
PAPER: dict[str, float] = {
    "ransac_rho_std_mm_106cm": 3.9,
    "ransac_rho_std_mm_156cm": 8.8,
    "hough_rho_std_mm_106cm": 2.5,
    "hough_rho_std_mm_156cm": 7.4,
}


@dataclass(frozen=True)
class WallExperiment(MappingExperiment):
    """Experiment II: the error in rho of a flat wall's points (III-B, Table III)."""

    name: str = KIND
    """Scenario name."""
    distances_m: tuple[float, ...] = (1.06, 1.56)
    """Camera-to-wall distances (106 cm, then 50 cm further)."""
    frames: int = 20
    """Noisy frames per distance."""
    gate_m: float = 0.05
    """Points within this distance of the detected wall count as the wall's measurements."""
    scene: WallScene = field(default_factory=WallScene)
    """Wall rig geometry."""

    def __post_init__(self) -> None:
        if not self.distances_m or not all(d > 0 for d in self.distances_m):
            raise InputError(f"distances_m: expected positive distances, got {self.distances_m!r}")
        require_int(self, "", "frames")
        require_positive(self, "", "gate_m")


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
    cfg: WallExperiment, di: int, draws: list[int], acc: SparseAccumulator, rec: Any, bar: Any
) -> dict[str, _WallTally]:
    """Capture the noisy frames at distance ``di`` and measure the wall in each."""
    intr, dist = cfg.sensor.intrinsics, cfg.distances_m[di]
    rig = build_wall_rig(dist, cfg.scene, intr)
    cam = rig.camera(cfg.sensor.kinect())
    rot = rig.world_from_camera[:3, :3]
    tally = {a: _WallTally() for a in ALGORITHMS}
    try:
        for f in range(cfg.frames):
            i = di * cfg.frames + f
            depth = cam.capture(rig.data, draws[2 * i] % (2**31))
            pts, _ = depth_to_cloud(depth, intr, rot, stride=cfg.detectors.stride)
            if rec is not None:
                rec.set_time(i, float(i))
            for alg in ALGORITHMS:
                det = detect(alg, pts, cfg.detectors, draws[2 * i + 1], acc)
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
    draws = seeds(seed, 2 * cfg.frames * len(cfg.distances_m))
    bar = progress_bar(progress, cfg.frames * len(cfg.distances_m), cfg.name)
    metrics: dict[str, float] = {}
    details: dict[str, Any] = {}
    acc = SparseAccumulator(cfg.detectors.hough)

    def work() -> None:
        for di, dist in enumerate(cfg.distances_m):
            tally = _wall_distance(cfg, di, draws, acc, rec, bar)
            for alg in ALGORITHMS:
                tally[alg].summarize(alg, f"{round(dist * 100)}cm", dist, metrics, details)

    stop = until_stopped(work, bar)
    return metrics, details, stop


def _measure(cfg: WallExperiment, seed: int, progress: bool | None, out_dir: Path | None, rec: Any) -> tuple[dict, dict, Stop, list[str]]:
    return (*measure_wall(cfg, seed, progress, rec), [])


EXPERIMENTS = {KIND: mapping_experiment(KIND, PAPER, WallExperiment, _measure)}
