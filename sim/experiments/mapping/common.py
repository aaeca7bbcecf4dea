"""What PlaneMap's three experiments share: the header every scenario file of theirs has
(:class:`MappingExperiment`: name, description, seed, the Kinect and both detectors),
the detectors' call, the seeds, and how a measurement's loop ends (:class:`Stop`).

Point clouds are handed to the detectors in a sensor-centred frame with z up (the
camera's rotation to the world applied, its position not), so rho is the distance from
the camera and the Hough accumulator's pole points at the ceiling.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from autonomy.common.errors import require_int
from autonomy.perception.camera import CameraIntrinsics
from autonomy.planes import (
    HoughConfig,
    PlaneDetection,
    RansacConfig,
    SparseAccumulator,
    hough_planes,
    ransac_planes,
)
from sim.simulator.kinect import KinectConfig
from sim.simulator.kinect_noise import KinectNoiseConfig

#: The two plane detectors every experiment compares, in the report's order.
ALGORITHMS = ("ransac", "hough")


@dataclass(frozen=True)
class SensorConfig:
    """The depth camera of a rig: intrinsics, noise model and rendering backend."""

    intrinsics: CameraIntrinsics = field(default_factory=CameraIntrinsics)
    """Pinhole intrinsics (640 x 480, f = 580 px)."""
    noise: KinectNoiseConfig = field(default_factory=KinectNoiseConfig)
    """Kinect noise model (every term switchable)."""
    backend: str = "auto"
    """auto, gl or raycast (see sim.simulator.kinect)."""

    def kinect(self) -> KinectConfig:
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
class MappingExperiment:
    """The fields every mapping experiment's scenario file has; each experiment's
    configuration adds its own (and names itself in ``name``'s default)."""

    name: str = ""
    """Scenario name."""
    description: str = ""
    """One line on what it shows."""
    seed: int = 0
    """Seed of every draw: sensor noise, the detectors (and the corridor's odometry noise)."""
    base_dir: str = "."
    """Directory of the scenario file (set by the loader)."""
    sensor: SensorConfig = field(default_factory=SensorConfig)
    """The Kinect."""
    detectors: DetectorsConfig = field(default_factory=DetectorsConfig)
    """RANSAC and Hough parameters."""


def detect(alg: str, pts: np.ndarray, det: DetectorsConfig, seed: int, acc: SparseAccumulator | None = None) -> PlaneDetection:
    """The planes ``alg`` (ransac or hough) finds in ``pts``."""
    if alg == "ransac":
        return ransac_planes(pts, det.ransac, seed)
    return hough_planes(pts, det.hough, seed, acc)


def seeds(seed: int, n: int) -> list[int]:
    """``n`` 32-bit seeds drawn from ``seed``."""
    return [int(s) for s in np.random.SeedSequence(int(seed)).generate_state(n, dtype=np.uint32)]


def finite(v: float) -> float | None:
    """``v`` rounded for the report; None when it is missing or not finite."""
    return round(float(v), 4) if v is not None and math.isfinite(float(v)) else None


def median(xs: list[float]) -> float:
    """The median of ``xs`` (NaN when empty)."""
    return float(np.median(xs)) if xs else float("nan")


@dataclass(frozen=True)
class Stop:
    """How a measurement's loop ended early: Ctrl-C, or the error that stopped it."""

    interrupted: bool = False
    error: Exception | None = None

    @property
    def early(self) -> bool:
        return self.interrupted or self.error is not None


def until_stopped(work: Callable[[], None], bar: Any, *close: Callable[[], None]) -> Stop:
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


def progress_bar(progress: bool | None, total: int, desc: str) -> Any:
    """A tqdm bar of ``total`` frames when ``progress`` (None: when stderr is a terminal)."""
    show = progress if progress is not None else sys.stderr.isatty()
    if not show:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame", leave=False)
