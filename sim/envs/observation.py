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
from autonomy.navigation.plan import Plan
from autonomy.perception.camera import CameraIntrinsics
from autonomy.perception.fspf import FSPFResult
from sim.envs.config import EnvConfig
from sim.envs.geometry import KCScanner
from sim.envs.loop import Reading

#: Bound of the ``goal`` observation (metres); values beyond are clipped.
GOAL_LIMIT_M = 1000.0
#: Bound of positions in ``pose_estimate`` (metres).
POSITION_LIMIT_M = 1.0e4
#: Bound of the ``plan`` points (in units of ``ranges_max_m``).
PLAN_LIMIT = 10.0
#: Bound of ``velocity`` (fractions of the action's scale; a push can exceed 1).
VELOCITY_LIMIT = 2.0


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
    depth: bool = True
    """Whether there is a ``depth`` key."""
    goal_unit: bool = False
    """'unit' goals: (distance / ``goal_scale_m`` capped at 1, cos, sin of the bearing)."""
    goal_scale_m: float = 10.0
    n_ranges: int = 0
    """Bins of ``ranges`` (0: no ``ranges`` key)."""
    ranges_max_m: float = 4.0
    history: int = 1
    """Decisions of ``ranges`` stacked."""
    n_plan: int = 0
    """Points of ``plan`` (0: no ``plan`` key)."""
    plan_spacing_m: float = 1.0
    velocity_scale: np.ndarray | None = None
    """``velocity``'s divisors (the action's scale; None: no ``velocity`` key)."""

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
            depth=cfg.observe_depth,
            goal_unit=cfg.goal_format == "unit",
            goal_scale_m=cfg.goal_scale_m,
            n_ranges=cfg.observe_ranges,
            ranges_max_m=cfg.ranges_max_m,
            history=cfg.history,
            n_plan=cfg.observe_plan,
            plan_spacing_m=cfg.plan_spacing_m,
            velocity_scale=cfg.action_scale if cfg.observe_velocity else None,
        )

    def space(self) -> spaces.Dict:
        """The observation space (a Dict of float32 boxes, depth possibly uint8)."""
        h, w = self.depth_shape
        shape = {"hwc": (h, w, 1), "chw": (1, h, w), "hw": (h, w)}[self.depth_layout]
        obs: dict[str, spaces.Space] = {}
        if self.depth:
            obs["depth"] = (
                spaces.Box(0, 255, shape, np.uint8)
                if self.depth_dtype == "uint8"
                else spaces.Box(0.0, self.depth_max_m, shape, np.float32)
            )
        if self.goal_unit:
            obs["goal"] = spaces.Box(np.array([0.0, -1.0, -1.0], np.float32), np.ones(3, np.float32), dtype=np.float32)
        elif self.goal_polar:
            obs["goal"] = spaces.Box(np.array([0.0, -np.pi], np.float32), np.array([GOAL_LIMIT_M, np.pi], np.float32), dtype=np.float32)
        else:
            obs["goal"] = spaces.Box(-GOAL_LIMIT_M, GOAL_LIMIT_M, (2,), np.float32)
        obs |= {
            "odometry": spaces.Box(
                np.array([-1.0, -1.0, -np.pi], np.float32), np.array([1.0, 1.0, np.pi], np.float32), dtype=np.float32
            ),
        }
        if self.n_points:
            obs["points"] = spaces.Box(self.points_low, self.points_high, dtype=np.float32)
        if self.scanner is not None:
            obs["scan"] = spaces.Box(0.0, np.float32(self.scanner.max_range_m), (self.scanner.n_bins,), np.float32)
        if self.n_ranges:
            obs["ranges"] = spaces.Box(0.0, 1.0, (self.history, self.n_ranges), np.float32)
        if self.n_plan:
            obs["plan"] = spaces.Box(-PLAN_LIMIT, PLAN_LIMIT, (self.n_plan, 2), np.float32)
        if self.velocity_scale is not None:
            obs["velocity"] = spaces.Box(-VELOCITY_LIMIT, VELOCITY_LIMIT, (3,), np.float32)
        if self.pose_estimate:
            L = POSITION_LIMIT_M
            obs["pose_estimate"] = spaces.Box(
                np.array([-L, -L, -np.pi, 0.0, 0.0], np.float32), np.array([L, L, np.pi, L, 10.0], np.float32), dtype=np.float32
            )
        return spaces.Dict(obs)

    def observe(
        self,
        reading: Reading,
        goal: np.ndarray,
        rng: np.random.Generator,
        known: np.ndarray | None = None,
        previous: dict[str, np.ndarray] | None = None,
    ) -> dict[str, np.ndarray]:
        """The observation of one frame; ``rng`` (the env's np_random) subsamples
        ``points``; ``known``: what the robot stack knows round the robot (robot frame,
        for ``ranges``); ``previous``: the last observation of the episode (None: the
        first), whose ``ranges`` the stack goes on from."""
        obs: dict[str, np.ndarray] = {}
        if self.depth:
            obs["depth"] = depth_observation(reading.depth, self.depth_layout, self.depth_dtype, self.depth_max_m)
        ref = reading.pose if self.goal_from_truth else reading.estimate
        if self.goal_unit:
            obs["goal"] = unit_goal_observation(ref, goal, self.goal_scale_m)
        else:
            obs["goal"] = goal_observation(ref, goal, self.goal_polar)
        obs["odometry"] = odometry_observation(reading.increment)
        if self.n_ranges:
            now = ranges_observation(np.zeros((0, 2)) if known is None else known, self.n_ranges, self.ranges_max_m)
            if previous is None:
                obs["ranges"] = np.repeat(now[None, :], self.history, axis=0)
            else:
                obs["ranges"] = np.vstack([now[None, :], previous["ranges"][:-1]])
        if self.n_plan:
            plan = None if reading.output is None or reading.output.plan is None else reading.output.plan.plan
            obs["plan"] = plan_observation(plan, reading.estimate, goal, self.n_plan, self.plan_spacing_m, self.ranges_max_m)
        if self.velocity_scale is not None:
            v = np.clip(reading.velocity / self.velocity_scale, -VELOCITY_LIMIT, VELOCITY_LIMIT)
            obs["velocity"] = v.astype(np.float32)
        if self.n_points:
            assert self.points_low is not None and self.points_high is not None
            planes = None if reading.output is None else reading.output.perception.planes
            obs["points"] = points_observation(planes, self.n_points, self.points_low, self.points_high, rng)
        if self.scanner is not None:
            obs["scan"] = self.scanner.scan(reading.depth)
        if self.pose_estimate:
            obs["pose_estimate"] = pose_estimate_observation(reading.estimate, reading.spread)
        return obs


def unit_goal_observation(reference_pose: np.ndarray, goal: np.ndarray, scale_m: float) -> np.ndarray:
    """The goal in the robot frame of ``reference_pose`` as (distance / ``scale_m`` capped
    at 1, cosine and sine of the bearing): every term in [-1, 1], the bearing without a
    jump behind the robot."""
    rel = relative_pose(reference_pose, np.array([goal[0], goal[1], 0.0]))[:2]
    d = math.hypot(rel[0], rel[1])
    c, s = (rel[0] / d, rel[1] / d) if d > 1e-9 else (1.0, 0.0)
    return np.array([min(d / scale_m, 1.0), c, s], dtype=np.float32)


def ranges_observation(points: np.ndarray, n_bins: int, max_m: float) -> np.ndarray:
    """The nearest of ``points`` (robot frame) in each of ``n_bins`` bearing bins all round
    the robot (bin 0 from straight behind, -pi, counter-clockwise), divided by ``max_m``
    and capped at 1 (1: nothing within ``max_m``)."""
    out = np.ones(n_bins, dtype=np.float32)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if not len(p):
        return out
    r = np.hypot(p[:, 0], p[:, 1])
    near = r < max_m
    if not near.any():
        return out
    k = np.floor((np.arctan2(p[near, 1], p[near, 0]) + math.pi) * (n_bins / (2.0 * math.pi))).astype(np.int64)
    np.minimum.at(out, np.clip(k, 0, n_bins - 1), (r[near] / max_m).astype(np.float32))
    return out


def plan_observation(
    plan: Plan | None, estimate: np.ndarray, goal: np.ndarray, n: int, spacing_m: float, scale_m: float
) -> np.ndarray:
    """``n`` points of the plan ``spacing_m`` apart ahead of the estimate's place on it
    (the last repeated past the plan's end; without a plan, the goal), in the robot frame
    of the estimate, divided by ``scale_m`` and clipped to +-PLAN_LIMIT."""
    if plan is None or len(plan.path) < 2:
        pts = np.repeat(np.asarray(goal, dtype=np.float64)[None, :2], n, axis=0)
    else:
        s0 = plan.project(np.asarray(estimate[:2], dtype=np.float64))
        pts = np.array([plan.point_at(min(s0 + (k + 1) * spacing_m, plan.length_m)) for k in range(n)])
    c, s = math.cos(float(estimate[2])), math.sin(float(estimate[2]))
    d = pts - np.asarray(estimate[:2], dtype=np.float64)
    rel = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]]) / scale_m
    return np.clip(rel, -PLAN_LIMIT, PLAN_LIMIT).astype(np.float32)


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
