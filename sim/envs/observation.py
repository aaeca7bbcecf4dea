"""The observations of ``DepthNav-v0``: their space, and the dict built from one frame.

:class:`Observations` is fixed by the config when the env is made (layout, dtype, which
optional keys, their bounds and the scanner) and turns each :class:`sim.envs.loop.Reading`
into the observation dict; the functions below build one key each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from autonomy.common.geometry import relative_pose
from autonomy.perception.camera import CameraIntrinsics
from autonomy.perception.fspf import FSPFResult
from sim.envs.config import EnvConfig
from sim.envs.geometry import KCScanner
from sim.envs.loop import Reading

#: Bound of the ``goal`` observation (metres); values beyond are clipped.
GOAL_LIMIT_M = 1000.0
#: Bound of positions in ``pose_estimate`` (metres).
POSITION_LIMIT_M = 1.0e4


@dataclass(frozen=True, eq=False)
class Observations:
    """What the observation holds and how each key is encoded, fixed when the env is made."""

    depth_layout: str
    """'hwc', 'chw' or 'hw' (EnvConfig.depth_layout)."""
    depth_dtype: str
    """'float32' (metres) or 'uint8' (scaled to the depth range)."""
    depth_shape: tuple[int, int]
    depth_max_m: float
    """The depth range: the float box's bound and the uint8 scale."""
    goal_polar: bool
    goal_from_truth: bool
    """Observe the goal relative to the true pose instead of the estimate."""
    n_points: int
    """Rows of ``points`` (0: no ``points`` key)."""
    points_low: np.ndarray | None
    points_high: np.ndarray | None
    scanner: KCScanner | None
    """The ``scan`` key's scanner (None: no ``scan`` key)."""
    pose_estimate: bool
    """Whether there is a ``pose_estimate`` key."""

    @classmethod
    def from_config(cls, cfg: EnvConfig, intrinsics: CameraIntrinsics, depth_max_m: float) -> Observations:
        """The observations of ``cfg`` for the camera at the observation's size."""
        h, w = cfg.depth_shape
        low = high = None
        if cfg.observe_points:
            rays = np.hypot(1.0, np.hypot(*(np.array([w, h]) / 2 / np.array([intrinsics.fx, intrinsics.fy]))))
            b = float(depth_max_m * rays + np.linalg.norm(cfg.kinect.mount.translation()) + 0.01)
            lo = np.array([-b, -b, -b, -1, -1, -1, 0, 0], np.float32)
            hi = np.array([b, b, b, 1, 1, 1, 1, 1], np.float32)
            low = np.broadcast_to(lo, (cfg.observe_points, 8)).copy()
            high = np.broadcast_to(hi, (cfg.observe_points, 8)).copy()
        scanner = (
            KCScanner(intrinsics, cfg.kinect.mount, cfg.observe_scan, cfg.scan_min_height_m, cfg.scan_max_height_m, depth_max_m)
            if cfg.observe_scan
            else None
        )
        return cls(
            depth_layout=cfg.depth_layout,
            depth_dtype=cfg.depth_dtype,
            depth_shape=cfg.depth_shape,
            depth_max_m=depth_max_m,
            goal_polar=cfg.goal_format == "polar",
            goal_from_truth=cfg.goal_from_truth,
            n_points=cfg.observe_points,
            points_low=low,
            points_high=high,
            scanner=scanner,
            pose_estimate=cfg.observe_pose_estimate,
        )

    def space(self) -> spaces.Dict:
        """The observation space (a Dict of float32 boxes, depth possibly uint8)."""
        h, w = self.depth_shape
        shape = {"hwc": (h, w, 1), "chw": (1, h, w), "hw": (h, w)}[self.depth_layout]
        obs: dict[str, spaces.Space] = {
            "depth": (
                spaces.Box(0, 255, shape, np.uint8)
                if self.depth_dtype == "uint8"
                else spaces.Box(0.0, self.depth_max_m, shape, np.float32)
            ),
            "goal": (
                spaces.Box(np.array([0.0, -np.pi], np.float32), np.array([GOAL_LIMIT_M, np.pi], np.float32), dtype=np.float32)
                if self.goal_polar
                else spaces.Box(-GOAL_LIMIT_M, GOAL_LIMIT_M, (2,), np.float32)
            ),
            "odometry": spaces.Box(
                np.array([-1.0, -1.0, -np.pi], np.float32), np.array([1.0, 1.0, np.pi], np.float32), dtype=np.float32
            ),
        }
        if self.n_points:
            obs["points"] = spaces.Box(self.points_low, self.points_high, dtype=np.float32)
        if self.scanner is not None:
            obs["scan"] = spaces.Box(0.0, np.float32(self.scanner.max_range_m), (self.scanner.n_bins,), np.float32)
        if self.pose_estimate:
            L = POSITION_LIMIT_M
            obs["pose_estimate"] = spaces.Box(
                np.array([-L, -L, -np.pi, 0.0, 0.0], np.float32), np.array([L, L, np.pi, L, 10.0], np.float32), dtype=np.float32
            )
        return spaces.Dict(obs)

    def observe(self, reading: Reading, goal: np.ndarray, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """The observation of one frame; ``rng`` (the env's np_random) subsamples ``points``."""
        obs = {
            "depth": depth_observation(reading.depth, self.depth_layout, self.depth_dtype, self.depth_max_m),
            "goal": goal_observation(reading.pose if self.goal_from_truth else reading.estimate, goal, self.goal_polar),
            "odometry": odometry_observation(reading.increment),
        }
        if self.n_points:
            assert self.points_low is not None and self.points_high is not None
            planes = None if reading.output is None else reading.output.perception.planes
            obs["points"] = points_observation(planes, self.n_points, self.points_low, self.points_high, rng)
        if self.scanner is not None:
            obs["scan"] = self.scanner.scan(reading.depth)
        if self.pose_estimate:
            obs["pose_estimate"] = pose_estimate_observation(reading.estimate, reading.spread)
        return obs


def goal_observation(reference_pose: np.ndarray, goal: np.ndarray, polar: bool = False) -> np.ndarray:
    """The goal in the robot frame of ``reference_pose``: (x, y) clipped to +-GOAL_LIMIT_M,
    or (distance, bearing) with the distance clipped to GOAL_LIMIT_M."""
    rel = relative_pose(reference_pose, np.array([goal[0], goal[1], 0.0]))[:2]
    if polar:
        return np.array([min(math.hypot(rel[0], rel[1]), GOAL_LIMIT_M), math.atan2(rel[1], rel[0])], dtype=np.float32)
    return np.clip(rel.astype(np.float32), -GOAL_LIMIT_M, GOAL_LIMIT_M)


def depth_observation(depth: np.ndarray, layout: str, dtype: str, depth_max_m: float) -> np.ndarray:
    """The depth frame (metres, 0 = invalid) in the observation's layout and type (a copy)."""
    if dtype == "uint8":
        d = np.where(depth > 0, np.clip(np.ceil(depth * (255.0 / depth_max_m)), 1, 255), 0).astype(np.uint8)
    else:
        d = depth.astype(np.float32, copy=True)
    if layout == "hwc":
        return d[:, :, None]
    if layout == "chw":
        return d[None, :, :]
    return d


def odometry_observation(increment: np.ndarray) -> np.ndarray:
    return np.clip(increment.astype(np.float32), np.array([-1, -1, -np.pi], np.float32), np.array([1, 1, np.pi], np.float32))


def pose_estimate_observation(estimate: np.ndarray, spread: tuple[float, float]) -> np.ndarray:
    L = POSITION_LIMIT_M
    pe = np.array([estimate[0], estimate[1], estimate[2], spread[0], spread[1]], dtype=np.float32)
    return np.clip(pe, np.array([-L, -L, -np.pi, 0, 0], np.float32), np.array([L, L, np.pi, L, 10.0], np.float32))


def points_observation(
    planes: FSPFResult | None, n_cap: int, low: np.ndarray, high: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """FSPF's points (plane points first, then outliers), padded or subsampled to ``n_cap``."""
    out = np.zeros((n_cap, 8), dtype=np.float32)
    if planes is None:
        return out
    n_p, n_o = len(planes.points), len(planes.outliers)
    total = n_p + n_o
    if total == 0:
        return out
    idx = np.arange(total)
    if total > n_cap:
        idx = np.sort(rng.choice(total, n_cap, replace=False))
    k = len(idx)
    is_p = idx < n_p
    ip, io = idx[is_p], idx[~is_p] - n_p
    m = len(ip)
    out[:m, :3] = planes.points[ip]
    out[:m, 3:6] = planes.normals[ip]
    out[:m, 6] = 1.0
    out[m:k, :3] = planes.outliers[io]
    out[:k, 7] = 1.0
    np.clip(out, low, high, out=out)
    return out
