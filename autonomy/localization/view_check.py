"""Does the view move the way the wheels say? A check of the depth camera against the odometry.

A robot that is carried away (kidnapped) or pushed sees a new view while its wheels
report no such motion. The map-based tests of :mod:`autonomy.localization.health` notice that only
once the short-term averages have fallen for seconds, and for those seconds the
navigator keeps placing the map's walls beside the robot, where the camera cannot see,
through a belief that is somewhere else, so a robot put down beside a door jamb can
drive into it. This check needs no map: the structure the camera saw in the last frame, moved by
the odometry since then, must appear where the current frame shows it (ours, the
frame-to-frame consistency behind visual odometry, used here only as a yes/no test).

Each fresh frame the pixels on a ``stride_px`` grid with a valid depth are back-projected
into the robot frame (:func:`sample_points`), and those below ``floor_m`` dropped: the
floor looks alike wherever the robot stands. Against the newest stored frame at least
``lag_s`` old (by default the last one; at most ``max_lag_s``, with at most
``max_gap_frames`` frames in between that were not stored), each stored point is
moved into the current robot frame by the odometry between the two frames, projected
into the current image, and compared with the depths within ``window_px`` of its pixel
(lateral noise and a little odometry error move it by a pixel or two): it **agrees** when
one of them is within ``tol_m + tol_per_m2 z^2 + movers_mps dt`` of its predicted depth z
(the Kinect's axial noise and disparity steps grow with z squared; people in view walk on
during the dt seconds between the two frames). It **disagrees** too when none of
them returned anything although z lies well inside the camera's range (``empty_margin_m``
from either end) and the image column returned the floor at a depth of z or more
(:func:`autonomy.perception.floor_rays.floor_reach`): the camera would have seen the point there.
A Kinect pixel returns nothing closer than its minimum range too; the floor seen that
far rules out a wall or a person that close in the column. The current frame's points
are compared with the stored image the same way. Points projected outside the image or
the camera's range, or onto pixels with no return near either end of the range, are not
compared. A frame with no valid pixel on the grid (a blackout, a blocked lens) compares
nothing.

The agreement fraction is NaN (no evidence) with fewer than ``min_points`` compared;
:class:`autonomy.localization.health.HealthMonitor` says lost when it falls below a threshold. Between
two frames a person walking in front of the camera moves a few centimetres (up to
``movers_mps`` times the time between them, allowed for), the robot's
odometry errs by a fraction of a degree, and a camera tilted by a bump keeps agreeing on
vertical walls. What the check cannot tell: a landing facing a plain wall at the same
distance as before, and a robot carried so slowly that its view changes little from one
frame to the next (the simulator's kidnapping is instantaneous; the map tests remain).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numba
import numpy as np

from autonomy.common.errors import InputError, require_int, require_non_negative, require_positive
from autonomy.common.geometry import points_from_frame, relative_pose
from autonomy.perception.camera import CameraIntrinsics, pixel_point_nb
from autonomy.perception.floor_rays import REACH_STRIDE_PX, floor_reach

__all__ = ["ViewCheckConfig", "ViewCheck", "sample_points", "view_agreement", "move_points"]


@dataclass(frozen=True)
class ViewCheckConfig:
    """Which pixels are compared, with which frame, and when two depths agree."""

    enabled: bool = True
    """Compare each frame with the one ``lag_s`` before (off: the health monitor gets no
    agreement and the view test never fires)."""
    stride_px: int = 8
    """Every this-many-th pixel in both directions of a 640 x 480 frame (4,800 samples)."""
    lag_s: float = 0.0
    """Compare with the newest stored frame at least this old: 0, the last fresh frame.
    A person walking in front of the camera moves a few centimetres between two frames
    but a few decimetres in 0.3 s, enough to make a view close to a person disagree with
    the belief right; a robot put down elsewhere changes its view between two frames ..."""
    max_lag_s: float = 0.5
    """... and no older than this (after a blackout there is nothing to compare with)."""
    max_gap_frames: int = 1
    """At most this many frames between the stored one and this one were not stored
    (blocked, or compared without evidence); after more, nothing is compared and this
    frame starts afresh. People walk on while nothing is compared: in a crowd, people
    close in front block the view for a few tenths of a second, and the first frames
    after it disagree with the frame before the blockage although the belief is right.
    Nearly every kidnapping the test notices is noticed against the frame just before
    the landing, so a longer gap would add false alarms and few kidnappings noticed."""
    floor_m: float = 0.1
    """Points lower than this above the floor are the floor, dropped."""
    tol_m: float = 0.05
    """Two depths agree within ``tol_m`` ..."""
    tol_per_m2: float = 0.01
    """... plus this times the depth squared (m per m^2) ..."""
    movers_mps: float = 2.0
    """... plus this speed times the time between the two frames: what the camera sees
    may have moved that fast meanwhile. People walk at up to 1.5-2 m/s (a walk and a
    step aside), 5-7 cm between two frames at 30 Hz, more than ``tol_m``: a person
    closing in on the robot fills its view, and every point of it would disagree while
    the belief is right. A robot carried or pushed away moves its view by decimetres or
    more, far beyond it (0: a static world)."""
    window_px: int = 2
    """The current depths within this many pixels of the predicted pixel are tried."""
    count_empty: bool = True
    """A point predicted onto pixels that all returned nothing disagrees, when its depth
    there lies ``empty_margin_m`` inside the camera's range and its image column returned
    the floor at least that deep. Only the floor counts: counting any return lower in
    the column, a robot turning to face a wall 0.8 m away, whose lower part the pitched
    camera still sees while points of the last frame fall on its unseen upper part,
    would be lost for nothing. A view of an open hall holds nothing but floor within the camera's
    4 m: compared only where both frames returned, a robot carried from such a view to a
    corridor, or the other way, would compare too few points to be judged and drive on
    its old belief ..."""
    empty_margin_m: float = 0.3
    """... so far inside the range: nearer the ends the Kinect's noise or a few
    centimetres of motion take a point in or out of range."""
    min_points: int = 300
    """With fewer compared points (both ways) the frame carries no evidence (NaN): a
    robot turning towards a person a metre away compares about a hundred points, most of
    them on the person, and few of them agree; a view of a room's or a corridor's
    walls compares a thousand or more."""

    def __post_init__(self) -> None:
        require_int(self, "recovery.view.", "stride_px", minimum=1)
        require_int(self, "recovery.view.", "window_px", minimum=0)
        require_int(self, "recovery.view.", "min_points", minimum=1)
        require_int(self, "recovery.view.", "max_gap_frames", minimum=0)
        require_positive(self, "recovery.view.", "max_lag_s", "tol_m")
        require_non_negative(self, "recovery.view.", "lag_s", "floor_m", "tol_per_m2", "empty_margin_m", "movers_mps")
        if self.lag_s > self.max_lag_s:
            raise InputError(f"recovery.view.lag_s: expected at most max_lag_s = {self.max_lag_s}, got {self.lag_s!r}")


def sample_points(depth: np.ndarray, intr: CameraIntrinsics, robot_from_camera: np.ndarray, stride: int, floor_m: float) -> np.ndarray:
    """Robot-frame points (n, 3) of the valid pixels on a ``stride`` grid of ``depth``
    (planar depth, 0 or non-finite = invalid) higher than ``floor_m`` above the floor."""
    rc = np.ascontiguousarray(robot_from_camera, dtype=np.float64)
    d = np.ascontiguousarray(depth, dtype=np.float32)
    return _sample_kernel(d, int(stride), float(intr.fx), float(intr.fy), float(intr.cx), float(intr.cy), rc[:3, :3].copy(), rc[:3, 3].copy(), float(floor_m))


@numba.njit(cache=True)
def _sample_kernel(depth, stride, fx, fy, cx, cy, rot, trans, floor_m):  # pragma: no cover - numba
    """:func:`sample_points` over the grid, row by row."""
    h, w = depth.shape
    out = np.empty(((h + stride - 1) // stride * ((w + stride - 1) // stride), 3))
    n = 0
    for v in range(0, h, stride):
        for u in range(0, w, stride):
            z = depth[v, u]
            if not (z > 0.0) or not math.isfinite(z):
                continue
            px, py, pz = pixel_point_nb(u, v, z, fx, fy, cx, cy, rot, trans)
            if pz <= floor_m:
                continue
            out[n, 0] = px
            out[n, 1] = py
            out[n, 2] = pz
            n += 1
    return out[:n].copy()


@numba.njit(cache=True)
def _agreement_kernel(pts, rot, trans, depth, reach, reach_su, fx, fy, cx, cy, zmin, zmax, tol_m, tol_q, win, empty_lo, empty_hi):  # pragma: no cover - numba
    """(compared, agreeing) of robot-frame ``pts`` against ``depth`` (module docstring);
    ``rot``, ``trans``: robot_from_camera. A point at a depth z in [``empty_lo``,
    ``empty_hi``] whose window returned nothing, in a column that returned the floor at
    a depth of z or more (``reach``, :func:`autonomy.perception.floor_rays.floor_reach`, one entry
    per ``reach_su`` columns), is compared and disagrees."""
    h, w = depth.shape
    n_cmp = 0
    n_ok = 0
    for i in range(pts.shape[0]):
        dx = pts[i, 0] - trans[0]
        dy = pts[i, 1] - trans[1]
        dz = pts[i, 2] - trans[2]
        # camera_from_robot is the transpose of the rotation.
        x = rot[0, 0] * dx + rot[1, 0] * dy + rot[2, 0] * dz
        y = rot[0, 1] * dx + rot[1, 1] * dy + rot[2, 1] * dz
        z = rot[0, 2] * dx + rot[1, 2] * dy + rot[2, 2] * dz
        if z < zmin or z > zmax:
            continue
        u = int(math.floor(fx * x / z + cx + 0.5))
        v = int(math.floor(fy * y / z + cy + 0.5))
        if u < 0 or u >= w or v < 0 or v >= h:
            continue
        tol = tol_m + tol_q * z * z
        # The predicted pixel first: on a view that agrees it settles almost every point.
        d = depth[v, u]
        if d > 0.0 and math.isfinite(d) and abs(d - z) <= tol:
            n_cmp += 1
            n_ok += 1
            continue
        seen = False
        ok = False
        for vv in range(max(0, v - win), min(h, v + win + 1)):
            for uu in range(max(0, u - win), min(w, u + win + 1)):
                d = depth[vv, uu]
                if not (d > 0.0) or not math.isfinite(d):
                    continue
                seen = True
                if abs(d - z) <= tol:
                    ok = True
                    break
            if ok:
                break
        if not seen:
            if empty_lo <= z <= empty_hi and reach[u // reach_su] >= z:
                n_cmp += 1
            continue
        n_cmp += 1
        if ok:
            n_ok += 1
    return n_cmp, n_ok


def view_agreement(
    pts: np.ndarray,
    depth: np.ndarray,
    intr: CameraIntrinsics,
    robot_from_camera: np.ndarray,
    min_range_m: float,
    max_range_m: float,
    tol_m: float,
    tol_per_m2: float,
    window_px: int,
    empty_margin_m: float | None = None,
    reach: np.ndarray | None = None,
) -> tuple[int, int]:
    """(compared, agreeing) points: robot-frame ``pts`` (n, 3) of an earlier frame, already
    moved into the current robot frame, against the current ``depth`` image. With
    ``empty_margin_m``, a point that far inside the range whose pixels returned nothing,
    in a column of ``depth`` that returned the floor at least as deep, disagrees; without,
    it is not compared. ``reach``: :func:`autonomy.perception.floor_rays.floor_reach` of ``depth``
    (through ``robot_from_camera``) if already known."""
    p = np.ascontiguousarray(pts, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(depth, dtype=np.float32)
    if d.shape != (intr.height, intr.width):
        raise InputError(f"view check: depth image expected {intr.height}x{intr.width}, got shape {d.shape}")
    rc = np.ascontiguousarray(robot_from_camera, dtype=np.float64)
    empty_lo, empty_hi = (math.inf, -math.inf) if empty_margin_m is None else (min_range_m + empty_margin_m, max_range_m - empty_margin_m)
    far = floor_reach(d, intr, rc) if reach is None else np.ascontiguousarray(reach, dtype=np.float32)
    n_cmp, n_ok = _agreement_kernel(
        p, rc[:3, :3].copy(), rc[:3, 3].copy(), d, far, REACH_STRIDE_PX, float(intr.fx), float(intr.fy), float(intr.cx), float(intr.cy),
        float(min_range_m), float(max_range_m), float(tol_m), float(tol_per_m2), int(window_px), float(empty_lo), float(empty_hi),
    )
    return int(n_cmp), int(n_ok)


def move_points(pts: np.ndarray, then: np.ndarray, now: np.ndarray) -> np.ndarray:
    """Robot-frame points (n, 3) seen at odometry pose ``then``, in the robot frame at
    ``now`` (heights unchanged)."""
    out = np.empty_like(pts)
    out[:, :2] = points_from_frame(relative_pose(now, then), pts[:, :2])
    out[:, 2] = pts[:, 2]
    return out


class ViewCheck:
    """The frames of the last ``max_lag_s`` and the agreement of each new one with them."""

    def __init__(self, cfg: ViewCheckConfig, intr: CameraIntrinsics, robot_from_camera: np.ndarray, min_range_m: float, max_range_m: float) -> None:
        self.cfg = cfg
        self.intr = intr
        self.min_range_m = float(min_range_m)
        self.max_range_m = float(max_range_m)
        self.set_mount(robot_from_camera)
        self.last = math.nan
        """The last frame's agreement fraction (NaN: no evidence)."""

    def set_mount(self, robot_from_camera: np.ndarray) -> None:
        """A new camera mount (the mount check corrected it): the stored frames were
        placed through the old one, so they are forgotten."""
        self.robot_from_camera = np.asarray(robot_from_camera, dtype=np.float64).copy()
        self.reset()

    def reset(self) -> None:
        """Forget the stored frames."""
        self._frames: deque[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = deque()
        """(time, odometry pose, sampled points, depth image, its floor reach) each."""
        self._gap = 0
        """Frames given to :meth:`update` since the last one stored."""

    def _agreement(self, pts: np.ndarray, then: np.ndarray, now: np.ndarray, depth: np.ndarray, reach: np.ndarray, dt: float) -> tuple[int, int]:
        """(compared, agreeing) of ``pts`` seen at odometry pose ``then`` against ``depth``
        (floor reach ``reach``) seen at ``now``, ``dt`` seconds apart."""
        if not len(pts):
            return 0, 0
        cfg = self.cfg
        return view_agreement(
            move_points(pts, then, now), depth, self.intr, self.robot_from_camera, self.min_range_m, self.max_range_m,
            cfg.tol_m + cfg.movers_mps * dt, cfg.tol_per_m2, cfg.window_px, cfg.empty_margin_m if cfg.count_empty else None, reach,
        )

    def _returned(self, depth: np.ndarray) -> bool:
        """Whether any pixel on the grid returned a depth (not a blackout or a blocked lens)."""
        return bool(np.any(depth[:: self.cfg.stride_px, :: self.cfg.stride_px] > 0.0))

    def _keep(self, t: float, odom: np.ndarray, pts: np.ndarray, depth: np.ndarray, reach: np.ndarray) -> bool:
        """Store this frame as a reference, unless the camera saw nothing on the grid
        (blocked): such a frame is no reference at all. Whether it was stored."""
        if not len(pts) and not self._returned(depth):
            self._gap += 1
            return False
        self._frames.append((float(t), np.asarray(odom, dtype=np.float64).copy(), pts, np.array(depth, dtype=np.float32), reach))
        self._gap = 0
        return True

    def store(self, t: float, odom: np.ndarray, depth: np.ndarray) -> None:
        """Keep this frame as the next one's reference without comparing it (nobody is
        listening: the stack is relocalizing)."""
        pts = sample_points(depth, self.intr, self.robot_from_camera, self.cfg.stride_px, self.cfg.floor_m)
        self._frames.clear()
        self._keep(t, odom, pts, depth, floor_reach(depth, self.intr, self.robot_from_camera))
        self.last = math.nan

    def update(self, t: float, odom: np.ndarray, depth: np.ndarray) -> float:
        """The agreement fraction of this frame (time ``t``, odometry pose ``odom``) with
        the newest stored frame at least ``lag_s`` old, both ways: that frame's points in
        this image and this frame's points in that image (a robot carried from an open
        hall, where the last view held nothing but floor, into a room is caught the
        second way). NaN: no stored frame, no valid pixel in this frame, or fewer than
        ``min_points`` compared. The frame is stored unless it has no valid depth, or was
        compared without evidence while showing ``min_points`` points or more; after
        more than ``max_gap_frames`` frames not stored, the stored ones are forgotten."""
        cfg = self.cfg
        frames = self._frames
        if self._gap > cfg.max_gap_frames:
            frames.clear()
        while frames and (t - frames[0][0] > cfg.max_lag_s or frames[0][0] > t):
            frames.popleft()
        ref = None
        for i in range(len(frames) - 1, -1, -1):
            if t - frames[i][0] >= cfg.lag_s:
                for _ in range(i):  # older ones will never be the newest old enough again
                    frames.popleft()
                ref = frames[0]
                break
        pts = sample_points(depth, self.intr, self.robot_from_camera, cfg.stride_px, cfg.floor_m)
        reach = floor_reach(depth, self.intr, self.robot_from_camera)
        frac = math.nan
        if ref is not None and self._returned(depth):
            t0, odom0, pts0, depth0, reach0 = ref
            dt = t - t0
            n1, ok1 = self._agreement(pts0, odom0, odom, depth, reach, dt)
            n2, ok2 = self._agreement(pts, odom, odom0, depth0, reach0, dt)
            if n1 + n2 >= cfg.min_points:
                frac = (ok1 + ok2) / (n1 + n2)
        # A frame showing something that could not be checked against a stored one does
        # not become the next one's reference while that one lasts: a landing whose first
        # view shares too few points with the last one would otherwise pass on the next
        # frame. A view of nothing but floor is kept: in an open hall each frame is, and
        # the landing that comes after one is judged against it.
        if ref is None or not math.isnan(frac) or len(pts) < cfg.min_points:
            self._keep(t, odom, pts, depth, reach)
        else:
            self._gap += 1
        self.last = frac
        return frac
