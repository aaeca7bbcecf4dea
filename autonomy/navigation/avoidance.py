"""Obstacle avoidance by open path lengths: BV2012, Section V, Eq. 3-5.

For a candidate direction theta with unit vector theta_hat, robot radius r and obstacle
points P u O down-projected to the floor plane (robot frame, x forward, y left):

- Eq. 3: P_theta = {p : ||p - (p . theta_hat) theta_hat|| < r}, the points inside the
  corridor of half-width r swept by the robot moving along theta.
- Eq. 4: d(theta) = min over p in P_theta with p . theta_hat > 0 of max(0, p . theta_hat - r),
  the open path length; ``max_range`` when no point blocks (and it is capped there: the
  sensor sees no further).
- Eq. 5: theta* = argmax_theta d(theta) cos(theta - theta_d).

Readings of the garbled text and choices made here:

- Only points strictly ahead (p . theta_hat > 0) block a direction: what lies behind the
  robot never stops it moving away. A point within r of the robot centre and ahead lies in
  the corridor (its lateral offset is at most its distance) with p . theta_hat - r < 0, so
  it blocks that direction with d = 0; the same point does not block directions pointing
  away from it (p . theta_hat <= 0, including exactly abeam).
- ``r`` in Eq. 3-4 is ``robot_radius_m + safety_margin_m`` (the margin widens the corridor
  and shortens the open length alike). Eq. 4 subtracts r, not the exact contact offset
  sqrt(r^2 - lateral^2): conservative by up to r for points near the corridor edge.
- The candidate fan spans theta_d +- fov_rad / 2 (theta_d wrapped to [-pi, pi]), clipped
  to [-pi, pi] so it never turns through the back; with a camera-width fan the chosen
  direction stays near where the camera looks (and can see obstacles). The sample nearest
  theta_d is replaced by theta_d itself, so the desired direction is always a candidate.
- Ties in Eq. 5 go to the candidate closest to theta_d (then the lower index, i.e. the
  more clockwise one).
- Safe speed: the largest v from which the robot stops within d(theta*) - stop_distance
  at the maximum deceleration a, v = sqrt(2 a max(0, d* - stop)); the caller caps it at
  its cruise speed. ``blocked`` when d* <= stop_distance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from autonomy.common.constants import KINECT_MAX_RANGE_M, ROBOT_RADIUS_M, SAFETY_MARGIN_M
from autonomy.common.errors import InputError
from autonomy.common.geometry import wrap_angle
from autonomy.perception.nearfield import NearFieldConfig


@dataclass(frozen=True)
class AvoidanceConfig:
    """Obstacle avoidance parameters (BV2012, Section V)."""

    robot_radius_m: float = ROBOT_RADIUS_M
    """r: robot radius (Eq. 3-4)."""
    safety_margin_m: float = SAFETY_MARGIN_M
    """Clearance added to r for the corridor test and open length (Eq. 3-4)."""
    max_range_m: float = KINECT_MAX_RANGE_M
    """Cap on the open path length d(theta): the depth sensor's range."""
    n_directions: int = 61
    """Number of candidate directions theta in the fan."""
    fov_rad: float = math.radians(90.0)
    """Angular width of the candidate fan, centred on theta_d (clipped to [-pi, pi])."""
    min_height_m: float = 0.05
    """Points lower than this above the floor are floor, not obstacles."""
    max_height_m: float = 1.1
    """Points higher than this are overhead (the robot passes below), not obstacles."""
    stop_distance_m: float = 0.05
    """Open length kept in reserve when stopping; d(theta*) at or below it means blocked."""
    max_decel_mps2: float = 1.0
    """a: maximum braking deceleration used for the safe speed."""
    near_field: NearFieldConfig = field(default_factory=NearFieldConfig)
    """Obstacles closer than the camera's minimum range, from the near floor it fails to
    see (ours, :mod:`autonomy.perception.nearfield`)."""

    def __post_init__(self) -> None:
        for name in ("robot_radius_m", "max_range_m", "max_decel_mps2", "fov_rad"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"avoidance.{name}: expected a positive number, got {v!r}")
        for name in ("safety_margin_m", "stop_distance_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InputError(f"avoidance.{name}: expected a number >= 0, got {v!r}")
        n = self.n_directions
        if not (isinstance(n, int) and not isinstance(n, bool) and n >= 1):
            raise InputError(f"avoidance.n_directions: expected an integer >= 1, got {n!r}")
        if self.fov_rad > 2.0 * math.pi:
            raise InputError(f"avoidance.fov_rad: expected an angle in (0, 2 pi], got {self.fov_rad!r}")
        for name in ("min_height_m", "max_height_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise InputError(f"avoidance.{name}: expected a finite number, got {v!r}")
        if not self.min_height_m < self.max_height_m:
            raise InputError(
                f"avoidance.min_height_m ({self.min_height_m!r}) must be below max_height_m ({self.max_height_m!r})"
            )

    @property
    def radius_m(self) -> float:
        """The r used in Eq. 3-4: robot radius plus safety margin."""
        return self.robot_radius_m + self.safety_margin_m


@dataclass(frozen=True)
class AvoidanceResult:
    """Outcome of one obstacle-avoidance decision (robot frame)."""

    angles: np.ndarray
    """theta: candidate directions (K,), radians, increasing."""
    lengths: np.ndarray
    """d(theta): open path length of each candidate (K,), metres (Eq. 4)."""
    best_index: int
    """Index of theta* in ``angles`` (Eq. 5)."""
    theta_star: float
    """theta*: chosen direction of travel, radians (Eq. 5)."""
    open_length_m: float
    """d(theta*): open path length along the chosen direction."""
    safe_speed_mps: float
    """Largest speed from which the robot stops within d(theta*) - stop distance."""
    blocked: bool
    """True when d(theta*) <= stop distance: no direction in the fan is open."""


@numba.njit(cache=True)
def _band_kernel(a, b, lo, hi, out):  # pragma: no cover - numba
    m = 0
    for src in (a, b):
        for i in range(src.shape[0]):
            x, y, z = src[i, 0], src[i, 1], src[i, 2]
            if z >= lo and z <= hi and math.isfinite(x) and math.isfinite(y) and math.isfinite(z):
                out[m, 0] = x
                out[m, 1] = y
                m += 1
    return m


def obstacle_points(points3d: np.ndarray, cfg: AvoidanceConfig | None = None, also: np.ndarray | None = None) -> np.ndarray:
    """(n, 3) robot-frame points (P u O) -> (k, 2) floor-plane obstacles inside the height band.

    Points with z outside [min_height_m, max_height_m] (floor, overhead) and non-finite
    points are dropped; the rest are down-projected to (x, y) (Section V). ``also`` is
    a second (m, 3) cloud taken after the first (FSPF's outliers O after its plane points
    P), without stacking the two.
    """
    cfg = AvoidanceConfig() if cfg is None else cfg
    clouds = []
    for name, c in (("points3d", points3d), ("also", np.zeros((0, 3)) if also is None else also)):
        arr = np.ascontiguousarray(c, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != 3:
            raise InputError(f"obstacle_points: expected {name} as an (n, 3) array, got shape {arr.shape}")
        clouds.append(arr)
    out = np.empty((len(clouds[0]) + len(clouds[1]), 2))
    m = _band_kernel(clouds[0], clouds[1], float(cfg.min_height_m), float(cfg.max_height_m), out)
    return out[:m]


@numba.njit(cache=True)
def _open_path_lengths_kernel(
    xs: np.ndarray, ys: np.ndarray, angles: np.ndarray, radius: float, max_range: float, out: np.ndarray
) -> None:
    """Eq. 3-4 for every angle: out[k] = min over blocking points of max(0, p . t - r)."""
    n = xs.shape[0]
    for k in range(angles.shape[0]):
        c = math.cos(angles[k])
        s = math.sin(angles[k])
        best = max_range
        for i in range(n):
            along = xs[i] * c + ys[i] * s  # p . theta_hat
            if along <= 0.0:
                continue  # behind (or abeam): does not block this direction
            lateral = ys[i] * c - xs[i] * s  # signed distance from the ray's line
            if abs(lateral) < radius:  # Eq. 3
                d = along - radius  # Eq. 4
                if d < best:
                    best = d
        out[k] = best if best > 0.0 else 0.0


def open_path_lengths(points2d: np.ndarray, angles: np.ndarray, radius: float, max_range: float) -> np.ndarray:
    """Open path length d(theta) (Eq. 3-4) for each robot-frame angle, capped at max_range.

    O(n * K) in one numba kernel; an empty cloud gives max_range everywhere.
    """
    pts = np.asarray(points2d, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise InputError(f"open_path_lengths: expected an (n, 2) array of points, got shape {pts.shape}")
    ang = np.ascontiguousarray(np.asarray(angles, dtype=np.float64).reshape(-1))
    if not (math.isfinite(radius) and radius >= 0):
        raise InputError(f"open_path_lengths: radius must be a number >= 0, got {radius!r}")
    if not (math.isfinite(max_range) and max_range > 0):
        raise InputError(f"open_path_lengths: max_range must be a positive number, got {max_range!r}")
    if not np.isfinite(ang).all():
        raise InputError("open_path_lengths: angles must be finite")
    out = np.empty(ang.shape[0], dtype=np.float64)
    xs = np.ascontiguousarray(pts[:, 0])
    ys = np.ascontiguousarray(pts[:, 1])
    _open_path_lengths_kernel(xs, ys, ang, float(radius), float(max_range), out)
    return out


def candidate_angles(desired_rad: float, cfg: AvoidanceConfig) -> np.ndarray:
    """The candidate fan: n_directions angles over theta_d +- fov/2 clipped to [-pi, pi], theta_d included."""
    if not math.isfinite(desired_rad):
        raise InputError(f"choose_direction: desired direction must be finite, got {desired_rad!r}")
    d = wrap_angle(float(desired_rad))
    half = 0.5 * cfg.fov_rad
    lo, hi = max(-math.pi, d - half), min(math.pi, d + half)
    angles = np.linspace(lo, hi, cfg.n_directions)
    angles[int(np.argmin(np.abs(angles - d)))] = d  # stays sorted: d lies between its neighbours
    return angles


def eq5_scores(angles: np.ndarray, lengths: np.ndarray, desired_rad: float, horizon_m: float | None = None) -> np.ndarray:
    """Eq. 5's d(theta) cos(theta - theta_d) per candidate, d capped at ``horizon_m`` when given."""
    d = lengths if horizon_m is None else np.minimum(lengths, horizon_m)
    return d * np.cos(angles - desired_rad)


def choose_direction(
    points2d: np.ndarray,
    desired_rad: float,
    cfg: AvoidanceConfig | None = None,
    static_points2d: np.ndarray | None = None,
    static_radius_m: float | None = None,
    horizon_m: float | None = None,
) -> AvoidanceResult:
    """theta* by Eq. 5 over the candidate fan around desired_rad, with its open length and safe speed.

    ``static_points2d`` (ours): known obstacles (map walls the camera cannot see) taken
    with their own radius ``static_radius_m`` (default ``cfg.radius_m``); d(theta) is the
    shorter of the two open lengths. ``horizon_m`` (ours; None = uncapped, as the paper):
    Eq. 5 scores d(theta) up to this, so that a direction open farther than it does not
    win over the desired one for that alone; the speed still comes from the full length.
    """
    cfg = AvoidanceConfig() if cfg is None else cfg
    angles = candidate_angles(desired_rad, cfg)
    d = wrap_angle(float(desired_rad))
    lengths = open_path_lengths(points2d, angles, cfg.radius_m, cfg.max_range_m)
    if static_points2d is not None and len(static_points2d):
        r = cfg.radius_m if static_radius_m is None else float(static_radius_m)
        lengths = np.minimum(lengths, open_path_lengths(static_points2d, angles, r, cfg.max_range_m))
    score = eq5_scores(angles, lengths, d, horizon_m)
    best = float(score.max())
    ties = np.flatnonzero(score >= best - 1e-12 * max(1.0, abs(best)))
    i = int(ties[np.argmin(np.abs(angles[ties] - d))])
    dstar = float(lengths[i])
    v = math.sqrt(2.0 * cfg.max_decel_mps2 * max(0.0, dstar - cfg.stop_distance_m))
    return AvoidanceResult(
        angles=angles,
        lengths=lengths,
        best_index=i,
        theta_star=float(angles[i]),
        open_length_m=dstar,
        safe_speed_mps=v,
        blocked=bool(dstar <= cfg.stop_distance_m),
    )
