"""Carrot following and the choice of direction and speed: the carrot on the plan and its
lane shift round what stands on the plan's line, Eq. 3-5 (:mod:`autonomy.navigation.avoidance`)
on the obstacles and the map's walls in the camera's blind spots with hysteresis on the
side, and the drive along the chosen direction (look first, slow near obstacles).
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import wrap_angle
from autonomy.navigation.avoidance import (
    AvoidanceConfig,
    AvoidanceResult,
    choose_direction,
    eq5_scores,
)
from autonomy.navigation.config import NavCommand, NavigatorConfig
from autonomy.navigation.plan import Plan
from autonomy.navigation.surroundings import Surroundings
from autonomy.perception.camera import DepthCamera

_LANE_STEP_M = 0.05
"""Spacing of the carrot shifts tried (:meth:`Steering.lane_offset`)."""

LaneFrame = tuple[np.ndarray, np.ndarray, np.ndarray, float]
"""The plan's frame for the lane shift: its point, unit tangent, left normal, and reach."""


def turn_rate(cfg: NavigatorConfig, angle: float) -> float:
    """Yaw rate turning towards a direction ``angle`` off the heading (``heading_gain``,
    at most ``max_turn_rate_rad_s``)."""
    return float(np.clip(cfg.heading_gain * angle, -cfg.max_turn_rate_rad_s, cfg.max_turn_rate_rad_s))


def _side_of(theta: float, desired: float, dead_band: float) -> int:
    d = wrap_angle(theta - desired)
    return 0 if abs(d) <= dead_band else (1 if d > 0 else -1)


class Steering:
    """The carrot and the direction; remembers the lane shift's and Eq. 5's chosen sides."""

    def __init__(self, cfg: NavigatorConfig, avoid: AvoidanceConfig, camera: DepthCamera, surroundings: Surroundings) -> None:
        self.cfg = cfg
        self.avoid = avoid
        self.camera = camera
        self.surroundings = surroundings
        self._side = 0
        """The side of the carrot direction Eq. 5's choice last lay on (:meth:`keep_side`)."""
        self._lane = 0.0
        """The side of the plan the carrot was last shifted to (:meth:`lane_offset`)."""

    def forget(self) -> None:
        """Forget the sides chosen (they were chosen on a pose estimate that jumped)."""
        self._lane = 0.0
        self._side = 0

    # -- the carrot ---------------------------------------------------------------------
    def carrot(self, plan: Plan, pose: np.ndarray, s: float, located: np.ndarray) -> np.ndarray:
        """The carrot: the plan's lookahead ahead of arc length ``s`` on it, shifted
        sideways round the ``located`` obstacles by :meth:`lane_offset`."""
        la = plan.lookahead(s)
        carrot = plan.point_at(s + la)
        shift = self.lane_offset(plan, pose, located, s)
        if shift:
            t0 = plan.point_at(s + la + 0.05) - plan.point_at(s + la - 0.05)
            t0 = t0 / max(1e-9, math.hypot(t0[0], t0[1]))
            carrot = carrot + shift * np.array([-t0[1], t0[0]])
        return carrot

    def toward_plan(self, plan: Plan, pose: np.ndarray) -> tuple[np.ndarray, float, float]:
        """The carrot on the plan (no lane shift), its direction in the robot frame and
        the yaw rate turning towards it."""
        xy = np.asarray(pose[:2], dtype=np.float64)
        if len(plan.path) < 2:
            return xy, 0.0, 0.0
        s = plan.project(xy)
        carrot = plan.point_at(s + plan.lookahead(s))
        d = carrot - xy
        desired = wrap_angle(math.atan2(d[1], d[0]) - float(pose[2]))
        return carrot, desired, turn_rate(self.cfg, desired)

    def lane_offset(self, plan: Plan, pose: np.ndarray, obstacles: np.ndarray, s: float) -> float:
        """Sideways shift (m, left of the plan positive) of the carrot (``lane_shift_m``).

        In the plan's frame at arc length ``s`` (its tangent, over the straight stretch
        ahead, at most ``lane_check_m`` and up to the next corner), an offset o is clear
        when no obstacle ahead (from the avoidance radius behind ``s`` on) lies within
        the avoidance radius of the line at o, nor a map wall within the robot radius
        plus ``map_clearance_m``. 0 when the plan's own line is clear (Eq. 5 as the paper)
        or no offset is; else the clear offset nearest 0, on the side chosen before while
        that side has one; the first choice is the side of the clear offset nearest the
        robot (on a tie the right).
        """
        shift = 0.0
        frame = self._lane_frame(plan, s) if self.cfg.lane_shift_m > 0 and len(plan.path) >= 2 else None
        if frame is not None:
            lats = self._lane_laterals(pose, obstacles, frame)
            # Most frames end here: the plan's own line is clear.
            if any(bool(np.any(np.abs(lat) < gap)) for lat, gap in lats):
                shift = self._pick_lane(pose, frame, lats)
        self._lane = float(np.sign(shift))
        return shift

    def _lane_frame(self, plan: Plan, s: float) -> LaneFrame | None:
        """The plan's frame for :meth:`lane_offset` at arc length ``s``: its point, unit
        tangent and left normal there, and how far ahead the stretch is checked
        (``lane_check_m``, up to the next corner and the plan's end); None when that is
        shorter than the avoidance radius or the plan has no direction there."""
        reach = self.cfg.lane_check_m
        ahead = plan.corners - s
        ahead = ahead[ahead > 0.0]
        if len(ahead):
            reach = min(reach, float(ahead.min()))
        reach = min(reach, float(plan.cum[-1]) - s)
        if reach < self.avoid.radius_m:
            return None
        p0 = plan.point_at(s)
        u = plan.point_at(s + min(reach, 0.5)) - p0 if reach > 1e-6 else np.zeros(2)
        nu = math.hypot(u[0], u[1])
        if nu < 1e-9:
            return None
        u = u / nu
        return p0, u, np.array([-u[1], u[0]]), reach

    def _lane_laterals(self, pose: np.ndarray, obstacles: np.ndarray, frame: LaneFrame) -> list[tuple[np.ndarray, float]]:
        """Lateral offsets (plan frame) of the obstacles and of the map's walls on the
        stretch ahead (from the avoidance radius behind its start to ``reach``), each with
        the gap it needs: the avoidance radius for sensed points, the robot radius plus
        ``map_clearance_m`` for walls."""
        cfg, r = self.cfg, self.avoid.radius_m
        p0, u, n, reach = frame
        c, sn = math.cos(float(pose[2])), math.sin(float(pose[2]))
        rel0 = np.asarray(pose[:2], dtype=np.float64) - p0
        # Plan-frame axes of robot-frame points (sensed) and of world-axes offsets (walls).
        ua, na = (c * u[0] + sn * u[1], -sn * u[0] + c * u[1]), (c * n[0] + sn * n[1], -sn * n[0] + c * n[1])
        a0, l0 = float(rel0 @ u), float(rel0 @ n)
        obs = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
        walls = self.surroundings.near_walls(pose, reach + cfg.lane_shift_m + r)
        lats = []
        for pts, (au, nu_), gap in (
            (obs, (ua, na), r),
            (walls, (u, n), self.avoid.robot_radius_m + cfg.map_clearance_m),
        ):
            if len(pts):
                a = pts[:, 0] * au[0] + pts[:, 1] * au[1] + a0
                lat = pts[:, 0] * nu_[0] + pts[:, 1] * nu_[1] + l0
                lats.append((lat[(a > -r) & (a < reach)], gap))
        return lats

    def _pick_lane(self, pose: np.ndarray, frame: LaneFrame, lats: list[tuple[np.ndarray, float]]) -> float:
        """The clear offset nearest the plan, on the side chosen before while that side
        has one (0 when none is clear); the first choice is the side of the clear offset
        nearest the robot."""
        cfg = self.cfg
        p0, _, n, _ = frame
        k = int(math.floor(cfg.lane_shift_m / _LANE_STEP_M + 1e-9))
        offsets = _LANE_STEP_M * np.arange(-k, k + 1)
        clear = np.ones(len(offsets), dtype=bool)
        for lat, gap in lats:
            lat = lat[np.abs(lat) < cfg.lane_shift_m + gap]
            if len(lat):
                clear &= ~(np.abs(lat[:, None] - offsets[None, :]) < gap).any(axis=0)
        if not clear.any():
            return 0.0
        side = self._lane
        if side == 0.0:
            # First choice: the clear offset nearest the robot (a tie: the right, since
            # people step to their right, the robot's left, out of its way).
            lat = float((np.asarray(pose[:2], dtype=np.float64) - p0) @ n)
            cost = np.where(clear, np.abs(offsets - lat) + 1e-9 * (offsets > 0), np.inf)
            side = 1.0 if offsets[int(np.argmin(cost))] > 0 else -1.0
        same = clear & (np.sign(offsets) == side)
        pick = same if same.any() else clear
        j = int(np.flatnonzero(pick)[np.argmin(np.abs(offsets[pick]))])
        return float(offsets[j])

    # -- the direction and the speed ----------------------------------------------------
    def choose_direction(self, pose: np.ndarray, obstacles: np.ndarray, desired: float, short: bool = False) -> AvoidanceResult:
        """Eq. 3-5 on the obstacles and the map's walls in the camera's blind spots,
        with hysteresis on the side (:meth:`keep_side`); ``short``: the carrot is short
        (``narrow_horizon_m``)."""
        static = self.surroundings.map_blind_spots(pose)
        horizon = self.cfg.narrow_horizon_m if short and self.cfg.narrow_horizon_m > 0 else None
        res = choose_direction(
            np.asarray(obstacles, dtype=np.float64).reshape(-1, 2),
            desired,
            self.avoid,
            static,
            self.avoid.robot_radius_m + self.cfg.map_clearance_m,
            horizon,
        )
        return self.keep_side(res, desired, horizon)

    def keep_side(self, res: AvoidanceResult, desired: float, horizon: float | None = None) -> AvoidanceResult:
        """Hysteresis on Eq. 5: once the robot swerves to one side of the carrot direction,
        it keeps to that side while a direction there scores at least ``side_hysteresis``
        of the best (flipping left-right-left in front of an obstacle wastes the approach)."""
        cfg = self.cfg
        band = math.radians(3.0)
        side = _side_of(res.theta_star, desired, band)
        prev = self._side
        if prev != 0 and side == -prev and not res.blocked:
            score = eq5_scores(res.angles, res.lengths, desired, horizon)
            same = np.array([_side_of(a, desired, band) != -prev for a in res.angles])
            if same.any():
                j = int(np.flatnonzero(same)[np.argmax(score[same])])
                if score[j] >= cfg.side_hysteresis * float(score.max()) and res.lengths[j] > self.avoid.stop_distance_m:
                    d = float(res.lengths[j])
                    v = math.sqrt(2.0 * self.avoid.max_decel_mps2 * max(0.0, d - self.avoid.stop_distance_m))
                    res = AvoidanceResult(res.angles, res.lengths, j, float(res.angles[j]), d, v, False)
                    side = prev
        self._side = side
        return res

    def obstacle_near_path(self, obstacles: np.ndarray, theta: float) -> bool:
        """Whether an obstacle point lies less than ``proximity_range_m`` ahead along
        ``theta`` and within the avoidance radius plus ``proximity_gap_m`` of that ray."""
        o = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
        if not len(o):
            return False
        c, s = math.cos(theta), math.sin(theta)
        along = o[:, 0] * c + o[:, 1] * s
        lateral = np.abs(o[:, 1] * c - o[:, 0] * s)
        near = (along > 0.0) & (along < self.cfg.proximity_range_m) & (lateral < self.avoid.radius_m + self.cfg.proximity_gap_m)
        return bool(near.any())

    def drive(self, obstacles: np.ndarray, carrot: np.ndarray, desired: float, speed: float, res: AvoidanceResult) -> NavCommand:
        """Drive along theta* at ``speed``, turning towards it (look where the robot goes);
        only turn while theta* lies outside the camera's view (``look_first``), and slow
        down near obstacles (``proximity_speed_mps``)."""
        cfg = self.cfg
        fan = (res.angles, res.lengths)
        th = res.theta_star
        omega = turn_rate(cfg, th)
        if abs(th) > 0.5 * self.camera.fov_h_rad:
            if cfg.look_first:
                return NavCommand(np.array([0.0, 0.0, omega]), "turning", carrot, desired, th, res.open_length_m, fan)
            if cfg.unseen_speed_mps > 0:
                speed = min(speed, cfg.unseen_speed_mps)
        if cfg.proximity_speed_mps > 0 and self.obstacle_near_path(obstacles, th):
            speed = min(speed, cfg.proximity_speed_mps)
        v = np.array([speed * math.cos(th), speed * math.sin(th), omega])
        return NavCommand(v, "driving", carrot, desired, th, res.open_length_m, fan)
