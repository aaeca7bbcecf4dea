"""Camera mount self-check: detect and correct a tilted depth-camera mount from the floor.

A bumped mount (a few degrees of pitch or roll the stack does not know about) rotates
every back-projected point: the floor appears sloped, far floor points rise into the
obstacle band and walls lean. The floor itself tells the error, because the robot stands
on it: in the camera's optical frame the floor is a plane ``u . p = -h`` whose unit
normal ``u`` (up) and distance ``h`` (the optical centre's height) depend only on how the
camera really sits, not on the mount the stack believes. This module's method (ours, not
from BV2012 or the plane-mapping paper):

1. Floor evidence, per frame. FSPF's plane points and normals (robot frame through the
   believed mount) go back to the optical frame exactly (the inverse of the mount
   transform). Candidates: points whose local-plane normal is within
   ``max_normal_tilt_rad`` of the believed up. Their component-wise median normal ``u0``
   is already close to the true up whatever they are (floor and furniture tops are
   parallel); the floor is the candidates whose distance below the camera along ``u0``
   is within ``max_height_offset_m`` of the believed height (tops of furniture and
   people are higher). A least-squares plane through those points, refit twice on the
   points within ``inlier_m`` of it, is the frame's floor; a frame counts as evidence
   when it has ``min_points`` inliers spread over ``min_spread_m`` in both directions
   of the plane (a strip of floor along a wall fixes only one direction).
2. Accumulation. The floor estimate is the least-squares plane of the summed zeroth,
   first and second moments of the inlier points (optical frame) of the last
   ``window_frames`` evidence frames: a windowed average that forgets an old mount
   completely once the window has passed. Frames without floor evidence (a blackout, a
   wall filling the view) change nothing. Because the moments live in the optical frame,
   a correction of the believed mount does not invalidate them.
3. The mount the floor implies. The optical-frame up ``u``, expressed in the level
   camera frame (``ROBOT_FROM_OPTICAL_LEVEL @ u`` = (-sin p cos r, sin r, cos p cos r)),
   gives the pitch ``p`` and the roll ``r`` (about the robot's forward axis) of
   :class:`TiltedCameraMount`, and ``h`` its height. Yaw does not change the floor and
   is not observable this way; forward and lateral offsets stay as believed.
4. Decision. The error of the believed mount is the angle between its up and the
   window's ``u`` (``tilt_error_deg``), with the pitch, roll and height differences.
   A corrected mount is proposed when at least ``min_frames`` evidence frames were seen
   since the start or the last correction, the window is consistent (the per-frame
   pitch and roll estimates' median absolute deviation below ``max_spread_deg``, and
   the medians of its older and newer halves within ``stable_deg``, so a window that
   straddles a bump waits), and the tilt error exceeds ``threshold_deg`` (or, with
   ``correct_height``, the height error exceeds ``height_threshold_m``).

The stack re-runs FSPF with the proposed mount from then on (and keeps feeding this
check, whose :attr:`MountCheck.mount` is then the proposed one). Under the Kinect model a
correctly mounted camera's window estimate stays below about 0.2 degrees, far below the
1 degree threshold (docs/fspf.md, "Mount self-check", has the measurements).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numba
import numpy as np

from autonomy.common.errors import InputError, require_int, require_positive
from autonomy.perception.camera import ROBOT_FROM_OPTICAL_LEVEL, CameraMount
from autonomy.perception.fspf import FSPFResult, smallest_eigvec3


@dataclass(frozen=True)
class TiltedCameraMount(CameraMount):
    """A :class:`CameraMount` that may also be rolled: leaned sideways about the robot's
    forward axis.

    ``rotation()`` is R_x(roll) times the plain mount's rotation (R_y(pitch)
    ROBOT_FROM_OPTICAL_LEVEL): the pitched camera turned about the robot's x axis.
    Positive roll raises the camera's left side (right-handed about x). With
    ``roll_rad`` 0 it is the plain mount.
    """

    roll_rad: float = 0.0
    """Roll about the robot's forward axis (after the pitch)."""

    def rotation(self) -> np.ndarray:
        """Rotation robot_from_optical (3 x 3)."""
        c, s = math.cos(self.roll_rad), math.sin(self.roll_rad)
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]) @ super().rotation()


def mount_roll_rad(mount: CameraMount) -> float:
    """The roll of a mount (0 for a plain :class:`CameraMount`)."""
    return float(mount.roll_rad) if isinstance(mount, TiltedCameraMount) else 0.0


def pitch_roll_from_up(up_optical: np.ndarray) -> np.ndarray:
    """Pitch and roll of :class:`TiltedCameraMount` that make the floor with optical-frame
    up ``up_optical`` (unit, (..., 3)) level: (..., 2) radians.

    In the level camera frame that up is R^T e_z = (-sin p cos r, sin r, cos p cos r).
    """
    g = np.asarray(up_optical, dtype=np.float64) @ ROBOT_FROM_OPTICAL_LEVEL.T
    g = g / np.linalg.norm(g, axis=-1, keepdims=True)
    return np.stack([np.arctan2(-g[..., 0], g[..., 2]), np.arcsin(np.clip(g[..., 1], -1.0, 1.0))], axis=-1)


def mount_from_floor(mount: CameraMount, up_optical: np.ndarray, height_m: float | None = None) -> TiltedCameraMount:
    """The mount with the pitch and roll (and, if given, the height) that put the floor
    with optical-frame unit normal ``up_optical`` level; offsets as in ``mount``."""
    pitch, roll = pitch_roll_from_up(up_optical)
    base = {f.name: getattr(mount, f.name) for f in fields(CameraMount)}
    base["pitch_down_rad"] = float(pitch)
    if height_m is not None:
        base["height_m"] = float(height_m)
    return TiltedCameraMount(**base, roll_rad=float(roll))


@dataclass(frozen=True)
class MountCheckConfig:
    """Parameters of the mount self-check (module docstring)."""

    max_normal_tilt_rad: float = math.radians(20.0)
    """Floor candidates: plane points whose normal is within this angle of the believed up."""
    max_height_offset_m: float = 0.15
    """Floor: candidates within this distance of the believed floor (along the candidates' median normal)."""
    inlier_m: float = 0.04
    """Refits (two): points within this distance of the previous fit."""
    min_points: int = 150
    """A frame is floor evidence with at least this many floor inliers ..."""
    min_spread_m: float = 0.15
    """... whose standard deviation along both in-plane principal directions is at least this."""
    window_frames: int = 30
    """The floor estimate and its stability come from the last this many evidence frames."""
    min_frames: int = 30
    """Evidence frames needed since the start or the last correction before proposing one."""
    stable_deg: float = 0.3
    """Stable: the medians of the window's older and newer halves (pitch and roll) within this ..."""
    max_spread_deg: float = 1.0
    """... and the per-frame estimates' median absolute deviation below this."""
    threshold_deg: float = 1.0
    """Propose a correction when the believed mount's tilt error exceeds this."""
    correct_height: bool = True
    """Also correct (and trigger on) the camera height."""
    height_threshold_m: float = 0.03
    """Height error that triggers a correction (with ``correct_height``)."""

    def __post_init__(self) -> None:
        require_positive(
            self, "recovery.mount_check.", "max_normal_tilt_rad", "max_height_offset_m", "inlier_m", "min_spread_m",
            "stable_deg", "max_spread_deg", "threshold_deg", "height_threshold_m",
        )
        require_int(self, "recovery.mount_check.", "min_points", minimum=3)
        require_int(self, "recovery.mount_check.", "window_frames", "min_frames")
        if self.max_normal_tilt_rad >= math.pi / 2:
            raise InputError(f"recovery.mount_check.max_normal_tilt_rad: expected an angle below pi/2, got {self.max_normal_tilt_rad!r}")
        if not isinstance(self.correct_height, bool):
            raise InputError(f"recovery.mount_check.correct_height: expected a bool, got {self.correct_height!r}")


@dataclass(frozen=True)
class FloorFit:
    """One frame's floor in the optical frame."""

    up: np.ndarray
    """Unit normal, pointing from the floor towards the camera (3,)."""
    height_m: float
    """Distance of the optical centre above the floor."""
    points: int
    """Inlier points of the fit."""
    moments: tuple[float, np.ndarray, np.ndarray]
    """Sum of 1, p and p p^T over the inliers (optical frame)."""


@dataclass(frozen=True)
class MountEvidence:
    """What the self-check knows, for health reports."""

    tilt_deg: float
    """Angle between the believed mount's up and the floor's (nan before any floor)."""
    pitch_error_deg: float
    """Floor-implied pitch minus believed pitch (positive: the camera points lower than believed)."""
    roll_error_deg: float
    """Floor-implied roll minus believed roll."""
    height_error_m: float
    """Floor-implied camera height minus believed height."""
    frames_used: int
    """Evidence frames since the start or the last correction."""
    frames_total: int
    """Evidence frames in all."""
    stable: bool
    """The window of per-frame estimates is consistent (module docstring, step 4)."""
    corrections: int
    """Corrected mounts proposed so far."""


@numba.njit(cache=True)
def _floor_kernel(points, normals, rot, t, height, cos_gate, height_gate, inlier, pc, out):  # pragma: no cover - numba
    """Step 1 of the module docstring; ``out`` gets [inliers, up (3), lambda_1, sum p (3), sum p p^T (9)]."""
    out[:] = 0.0
    # Candidates: normal within the gate of the believed up (R^T e_z = rot[2]), to the optical frame.
    nc = np.empty((len(points), 3))
    m = 0
    for i in range(len(points)):
        a0 = normals[i, 0] * rot[0, 0] + normals[i, 1] * rot[1, 0] + normals[i, 2] * rot[2, 0]
        a1 = normals[i, 0] * rot[0, 1] + normals[i, 1] * rot[1, 1] + normals[i, 2] * rot[2, 1]
        a2 = normals[i, 0] * rot[0, 2] + normals[i, 1] * rot[1, 2] + normals[i, 2] * rot[2, 2]
        if not a0 * rot[2, 0] + a1 * rot[2, 1] + a2 * rot[2, 2] > cos_gate:  # NaN fails too
            continue
        q0, q1, q2 = points[i, 0] - t[0], points[i, 1] - t[1], points[i, 2] - t[2]
        if not math.isfinite(q0 + q1 + q2):
            continue
        nc[m, 0], nc[m, 1], nc[m, 2] = a0, a1, a2
        pc[m, 0] = q0 * rot[0, 0] + q1 * rot[1, 0] + q2 * rot[2, 0]
        pc[m, 1] = q0 * rot[0, 1] + q1 * rot[1, 1] + q2 * rot[2, 1]
        pc[m, 2] = q0 * rot[0, 2] + q1 * rot[1, 2] + q2 * rot[2, 2]
        m += 1
    if m < 3:
        return
    u0 = np.empty(3)
    for j in range(3):
        u0[j] = np.median(nc[:m, j])
    u0 /= math.sqrt(u0[0] * u0[0] + u0[1] * u0[1] + u0[2] * u0[2])
    # First the floor by its height below the camera along u0, then twice by the fit's residual.
    u = u0.copy()
    off = -height
    gate = height_gate
    s1 = np.zeros(3)
    s2 = np.zeros((3, 3))
    cov = np.zeros((3, 3))
    n = 0
    for _ in range(3):
        n = 0
        s1[:] = 0.0
        s2[:, :] = 0.0
        for i in range(m):
            if abs(pc[i, 0] * u[0] + pc[i, 1] * u[1] + pc[i, 2] * u[2] - off) >= gate:
                continue
            n += 1
            for j in range(3):
                s1[j] += pc[i, j]
                for k in range(3):
                    s2[j, k] += pc[i, j] * pc[i, k]
        if n < 3:
            return
        c = s1 / n
        cov = s2 / n - np.outer(c, c)
        u = smallest_eigvec3(cov)
        if u[0] * u0[0] + u[1] * u0[1] + u[2] * u0[2] < 0.0:
            u = -u
        off = u[0] * c[0] + u[1] * c[1] + u[2] * c[2]
        gate = inlier
    # The second eigenvalue from the invariants: l1 + l2 = tr - l0, l1 l2 = e2 - l0 (l1 + l2).
    l0 = 0.0
    for j in range(3):
        for k in range(3):
            l0 += u[j] * cov[j, k] * u[k]
    tr = cov[0, 0] + cov[1, 1] + cov[2, 2]
    e2 = (cov[0, 0] * cov[1, 1] - cov[0, 1] ** 2) + (cov[0, 0] * cov[2, 2] - cov[0, 2] ** 2) + (cov[1, 1] * cov[2, 2] - cov[1, 2] ** 2)
    s = tr - l0
    p = e2 - l0 * s
    out[0] = n
    out[1:4] = u
    out[4] = (s - math.sqrt(max(s * s - 4.0 * p, 0.0))) / 2.0
    out[5:8] = s1
    out[8:17] = s2.ravel()


def floor_fit(points: np.ndarray, normals: np.ndarray, mount: CameraMount, cfg: MountCheckConfig) -> FloorFit | None:
    """The floor in the optical frame from robot-frame plane points and normals seen
    through ``mount`` (step 1 of the module docstring), or None without enough evidence."""
    if len(points) < cfg.min_points:
        return None
    out = np.empty(17)
    _floor_kernel(
        np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(normals, dtype=np.float64),
        mount.rotation(), mount.translation(), float(mount.height_m), math.cos(cfg.max_normal_tilt_rad),
        float(cfg.max_height_offset_m), float(cfg.inlier_m), np.empty((len(points), 3)), out,
    )
    n = int(out[0])
    if n < cfg.min_points or out[4] < cfg.min_spread_m**2:
        return None
    up = out[1:4].copy()
    s1, s2 = out[5:8].copy(), out[8:17].reshape(3, 3).copy()
    return FloorFit(up=up, height_m=float(-(up @ s1) / n), points=n, moments=(float(n), s1, s2))


class MountCheck:
    """Watches the floor in FSPF's plane points and proposes a corrected camera mount
    when the believed one is tilted (module docstring)."""

    def __init__(self, mount: CameraMount, cfg: MountCheckConfig = MountCheckConfig()) -> None:
        if not isinstance(mount, CameraMount):
            raise InputError(f"mount: expected a CameraMount, got {type(mount).__name__}")
        if not isinstance(cfg, MountCheckConfig):
            raise InputError(f"cfg: expected a MountCheckConfig, got {type(cfg).__name__}")
        self.cfg = cfg
        self._mount = mount
        self._up_b = mount.rotation()[2]
        # The last window_frames evidence frames, a ring: up (3), height, then the moments
        # n, sum p (3), sum p p^T (9), all in the optical frame.
        self._ring = np.zeros((cfg.window_frames, 17))
        self._frames_used = 0
        self._frames_total = 0
        self._corrections = 0
        self._est: tuple[np.ndarray, float] | None = None  # the window's floor (up, height)
        self.corrected_from_deg = math.nan
        """The tilt error (degrees) that made the last correction (NaN before any)."""

    @property
    def mount(self) -> CameraMount:
        """The mount currently believed (the last proposed one, or the initial mount)."""
        return self._mount

    @property
    def tilt_error_deg(self) -> float:
        """The latest estimate of the believed mount's tilt error in degrees (nan before any floor)."""
        if self._est is None:
            return math.nan
        return math.degrees(math.acos(min(1.0, float(self._est[0] @ self._up_b))))

    def estimated_mount(self) -> TiltedCameraMount | None:
        """The mount the window's floor implies (None before any floor)."""
        if self._est is None:
            return None
        up, h = self._est
        return mount_from_floor(self._mount, up, h if self.cfg.correct_height else None)

    def evidence(self) -> MountEvidence:
        """Estimate and bookkeeping for health reports."""
        if self._est is None:
            dp = dr = dh = math.nan
        else:
            est = mount_from_floor(self._mount, self._est[0], self._est[1])
            dp = math.degrees(est.pitch_down_rad - self._mount.pitch_down_rad)
            dr = math.degrees(est.roll_rad - mount_roll_rad(self._mount))
            dh = est.height_m - self._mount.height_m
        return MountEvidence(
            tilt_deg=self.tilt_error_deg, pitch_error_deg=dp, roll_error_deg=dr, height_error_m=dh,
            frames_used=self._frames_used, frames_total=self._frames_total, stable=self._stable(),
            corrections=self._corrections,
        )

    def correction_event(self, t: float, mount: CameraMount) -> dict:
        """The event-log record of a corrected ``mount`` (normally the one :meth:`update`
        just proposed) at time ``t`` (s): the tilt error that made the correction
        (:attr:`corrected_from_deg`; after it the check's own error is about 0) and the
        mount's pitch and roll in degrees."""
        return {
            "t": round(t, 3), "event": "mount corrected", "tilt_error_deg": round(float(self.corrected_from_deg), 2),
            "pitch_down_deg": round(math.degrees(float(mount.pitch_down_rad)), 2), "roll_deg": round(math.degrees(mount_roll_rad(mount)), 2),
        }

    def _stable(self) -> bool:
        """A full window whose per-frame pitch and roll agree: small median absolute
        deviation, and the older and newer halves' medians within ``stable_deg``."""
        w = self.cfg.window_frames
        if self._frames_total < w:
            return False
        order = (np.arange(w) + self._frames_total) % w  # oldest first
        pr = pitch_roll_from_up(self._ring[order, :3])
        med = np.median(pr, axis=0)
        mad = np.median(np.abs(pr - med), axis=0)
        drift = np.abs(np.median(pr[: w // 2], axis=0) - np.median(pr[w // 2 :], axis=0))
        return bool(drift.max() < math.radians(self.cfg.stable_deg) and mad.max() < math.radians(self.cfg.max_spread_deg))

    def update(self, planes: FSPFResult) -> CameraMount | None:
        """Take one frame's FSPF result (computed with :attr:`mount`); return a corrected
        mount when one is proposed this frame, else None."""
        fit = floor_fit(planes.points, planes.normals, self._mount, self.cfg)
        if fit is None:
            return None
        row = self._ring[self._frames_total % self.cfg.window_frames]
        row[:3], row[3] = fit.up, fit.height_m
        row[4], row[5:8], row[8:] = fit.moments[0], fit.moments[1], fit.moments[2].ravel()
        self._frames_used += 1
        self._frames_total += 1
        tot = self._ring[: min(self._frames_total, self.cfg.window_frames), 4:].sum(axis=0)
        c = tot[1:4] / tot[0]
        up = smallest_eigvec3(tot[4:].reshape(3, 3) / tot[0] - np.outer(c, c))
        if up @ fit.up < 0.0:
            up = -up
        self._est = (up, float(-(up @ c)))
        if self._frames_used < self.cfg.min_frames:
            return None
        tilted = self.tilt_error_deg > self.cfg.threshold_deg
        lifted = self.cfg.correct_height and abs(self._est[1] - self._mount.height_m) > self.cfg.height_threshold_m
        if not (tilted or lifted) or not self._stable():
            return None
        new = self.estimated_mount()
        assert new is not None
        self.corrected_from_deg = self.tilt_error_deg
        self._mount = new
        self._up_b = new.rotation()[2]
        self._frames_used = 0
        self._corrections += 1
        return new
