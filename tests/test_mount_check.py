"""Mount self-check: a tilted camera found and corrected from the floor.

Depth frames are synthesised here by closed-form ray intersection (floor, a wall, boxes,
vertical cylinders for people) through a camera whose axes are built from its pitch and
roll with Rodrigues' formula, independently of ``CameraMount.rotation``; Kinect noise is
the simulator's model. FSPF then runs with the *nominal* mount, as the stack would.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.perception.camera import CameraIntrinsics, CameraMount
from autonomy.perception.fspf import FSPFConfig, fspf
from autonomy.perception.mount_check import (
    MountCheck,
    MountCheckConfig,
    TiltedCameraMount,
    floor_fit,
)
from sim.simulator.kinect_noise import KinectNoiseConfig, apply_kinect_noise
from tests.helpers import GL

INTR = CameraIntrinsics()
NOMINAL = CameraMount()


@dataclass(frozen=True)
class Scene:
    """Robot-frame scene: floor z = 0, a wall facing the robot, boxes and people."""

    wall_m: float = 3.5
    """The wall's distance ahead along its normal."""
    wall_yaw_rad: float = 0.0
    """Wall normal's angle from the robot's -x axis."""
    boxes: tuple[tuple[float, float, float, float, float], ...] = ()
    """(x0, x1, y0, y1, top): axis-aligned boxes standing on the floor."""
    people: tuple[tuple[float, float, float], ...] = ()
    """(x, y, radius): 1.7 m vertical cylinders."""


def camera_axes(pitch_rad: float, roll_rad: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Optical x (right), y (down), z (forward) in the robot frame: pitched down, then
    the whole camera turned by the roll about the robot's forward axis (positive: its
    left side up), by Rodrigues' formula."""
    f = np.array([math.cos(pitch_rad), 0.0, -math.sin(pitch_rad)])
    right = np.array([0.0, -1.0, 0.0])
    axes = (right, np.cross(f, right), f)
    k = np.array([1.0, 0.0, 0.0])
    c, s = math.cos(roll_rad), math.sin(roll_rad)
    return tuple(a * c + np.cross(k, a) * s + k * (k @ a) * (1.0 - c) for a in axes)  # type: ignore[return-value]


def render(scene: Scene, pitch_rad: float, roll_rad: float, height_m: float = NOMINAL.height_m, intr: CameraIntrinsics = INTR) -> np.ndarray:
    """Clean planar depth (float32, 0 = nothing within 4 m) of ``scene`` from a camera
    at ``height_m`` on the nominal forward offset with the given pitch and roll."""
    right, down, fwd = camera_axes(pitch_rad, roll_rad)
    u = (np.arange(intr.width) - intr.cx) / intr.fx
    v = (np.arange(intr.height) - intr.cy) / intr.fy
    d = u[None, :, None] * right + v[:, None, None] * down + fwd  # ray with unit optical z
    o = np.array([NOMINAL.forward_m, NOMINAL.lateral_m, height_m])
    dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
    best = np.full(dx.shape, np.inf)

    def hit(t: np.ndarray, ok: np.ndarray) -> None:
        np.minimum(best, np.where(ok & (t > 0), t, np.inf), out=best)

    with np.errstate(divide="ignore", invalid="ignore"):
        hit(-o[2] / dz, dz < 0)  # floor
        nw = np.array([-math.cos(scene.wall_yaw_rad), -math.sin(scene.wall_yaw_rad), 0.0])
        dn = d @ nw
        hit((-scene.wall_m - o @ nw) / dn, dn < 0)  # wall: nw . p = -wall_m
        for x0, x1, y0, y1, top in scene.boxes:  # slab method
            lo = np.array([x0, y0, 0.0])
            hi = np.array([x1, y1, top])
            ta, tb = (lo - o) / d, (hi - o) / d
            t_in = np.minimum(ta, tb).max(axis=-1)
            t_out = np.maximum(ta, tb).min(axis=-1)
            hit(t_in, t_in < t_out)
        for cx, cy, r in scene.people:
            px, py = o[0] - cx, o[1] - cy
            a = dx * dx + dy * dy
            b = px * dx + py * dy
            disc = b * b - a * (px * px + py * py - r * r)
            t = (-b - np.sqrt(np.maximum(disc, 0.0))) / a
            z = o[2] + t * dz
            hit(t, (disc > 0) & (z > 0) & (z < 1.7))
    best[~(best < 4.0)] = 0.0
    return best.astype(np.float32)


SCENES = (
    Scene(),
    Scene(wall_m=3.0, wall_yaw_rad=0.3, boxes=((1.6, 2.2, -0.9, -0.3, 0.45),)),
    Scene(wall_m=4.5, boxes=((2.0, 2.8, 0.2, 1.0, 0.75),), people=((2.2, -0.6, 0.2),)),
    Scene(wall_m=3.8, wall_yaw_rad=-0.4, boxes=((1.4, 1.9, 0.4, 0.9, 0.3), (2.6, 3.2, -1.2, -0.4, 0.72)), people=((1.8, 0.2, 0.18), (2.9, -0.3, 0.2))),
)


def frames(pitch_rad: float, roll_rad: float, n: int, *, height_m: float = NOMINAL.height_m, pattern_seed: int = 0, seed0: int = 0, scenes=SCENES):
    """``n`` noisy frames cycling through ``scenes`` (a fresh noise seed each)."""
    clean = [render(s, pitch_rad, roll_rad, height_m) for s in scenes]
    noise = KinectNoiseConfig(pattern_seed=pattern_seed)
    for i in range(n):
        yield apply_kinect_noise(clean[i % len(clean)], INTR, noise, seed=seed0 + i)


def run(check: MountCheck, depths, seed0: int = 0) -> list[tuple[int, CameraMount]]:
    """Feed frames through FSPF with the check's believed mount; the proposals made."""
    out = []
    for i, depth in enumerate(depths):
        new = check.update(fspf(depth, INTR, FSPFConfig(), seed=seed0 + i, mount=check.mount))
        if new is not None:
            out.append((i, new))
    return out


def floor_points(mount: CameraMount, depth: np.ndarray, seed: int = 99) -> np.ndarray:
    """Robot-frame FSPF plane points through ``mount`` with floor-like normals, low."""
    res = fspf(depth, INTR, FSPFConfig(), seed=seed, mount=mount)
    return res.points[(res.normals[:, 2] > math.cos(math.radians(20))) & (res.points[:, 2] < 0.4)]


def slope_deg(p: np.ndarray) -> float:
    """Angle from level of the least-squares plane z = a x + b y + c through ``p``."""
    a, b, _ = np.linalg.lstsq(np.column_stack([p[:, 0], p[:, 1], np.ones(len(p))]), p[:, 2], rcond=None)[0]
    return math.degrees(math.atan(math.hypot(a, b)))


@pytest.mark.parametrize(
    ("d_pitch_deg", "d_roll_deg"),
    [(3.0, 0.0), (-2.0, 0.0), (0.0, 3.0), (0.0, -2.5), (2.0, -2.0), (-1.5, 3.5)],
)
def test_tilted_mount_is_estimated_and_corrected(d_pitch_deg: float, d_roll_deg: float) -> None:
    p_true = NOMINAL.pitch_down_rad + math.radians(d_pitch_deg)
    r_true = math.radians(d_roll_deg)
    check = MountCheck(NOMINAL)
    proposals = run(check, frames(p_true, r_true, 40))
    assert len(proposals) == 1, proposals
    i, new = proposals[0]
    assert i == MountCheckConfig().min_frames - 1  # as soon as the evidence allows
    assert isinstance(new, TiltedCameraMount) and check.mount is new
    assert math.degrees(abs(new.pitch_down_rad - p_true)) < 0.3
    assert math.degrees(abs(new.roll_rad - r_true)) < 0.3
    assert abs(new.height_m - NOMINAL.height_m) < 0.02
    assert (new.forward_m, new.lateral_m) == (NOMINAL.forward_m, NOMINAL.lateral_m)
    assert check.tilt_error_deg < 0.05  # the believed mount now matches the estimate
    # The event records the error that made the correction, not the one left after it.
    assert check.correction_event(1.0, new)["tilt_error_deg"] == pytest.approx(math.hypot(d_pitch_deg, d_roll_deg), abs=0.4)
    # The floor is level again through the corrected mount (and was not through the nominal one).
    depth = next(frames(p_true, r_true, 1, seed0=500, scenes=(Scene(wall_m=4.5),)))
    before, after = floor_points(NOMINAL, depth), floor_points(new, depth)
    far = (after[:, 0] > 2.7) & (after[:, 0] < 3.3)
    assert far.sum() > 50
    assert np.abs(np.median(after[far, 2])) < 0.02  # level within 2 cm at 3 m
    assert np.percentile(np.abs(after[:, 2]), 95) < 0.05
    assert slope_deg(after) < 0.3
    # Through the nominal mount the floor had the true tilt.
    up_true, up_nominal = (np.array([a[2] for a in camera_axes(p, r)]) for p, r in ((p_true, r_true), (NOMINAL.pitch_down_rad, 0.0)))
    true_tilt = math.degrees(math.acos(up_true @ up_nominal))  # the angle between the two optical-frame ups
    assert abs(slope_deg(before) - true_tilt) < 0.3


def test_correct_mount_with_noise_proposes_nothing() -> None:
    """300 frames for each of two sensors' fixed noise patterns, with furniture and
    people: no proposal, and an estimate far below the threshold."""
    for pattern_seed in (0, 1):
        check = MountCheck(NOMINAL)
        assert run(check, frames(NOMINAL.pitch_down_rad, 0.0, 300, pattern_seed=pattern_seed, seed0=1000 * pattern_seed)) == []
        ev = check.evidence()
        assert ev.frames_used == ev.frames_total > 250  # the floor was seen, not missed
        assert ev.tilt_deg < 0.3
        assert abs(ev.height_error_m) < 0.015
        assert ev.corrections == 0 and check.mount is NOMINAL


def test_no_floor_no_evidence() -> None:
    """A wall filling the view, and blank frames: no estimate, no proposal."""
    check = MountCheck(NOMINAL)
    wall = Scene(wall_m=0.9)
    depths = list(frames(NOMINAL.pitch_down_rad + 0.1, 0.0, 5, scenes=(wall,))) + [np.zeros((INTR.height, INTR.width), np.float32)] * 3
    assert run(check, depths) == []
    assert math.isnan(check.tilt_error_deg) and check.evidence().frames_total == 0


def test_nan_and_empty_plane_points_are_no_evidence() -> None:
    """A broken frame's NaN points and an empty FSPF result change nothing."""
    from autonomy.perception.fspf import FSPFResult

    check = MountCheck(NOMINAL)
    res = fspf(render(SCENES[0], NOMINAL.pitch_down_rad, 0.0), INTR, FSPFConfig(), seed=1, mount=NOMINAL)
    pts, nrm = res.points.copy(), res.normals.copy()
    pts[::2] = np.nan
    nrm[1::2] = np.nan
    empty = np.zeros((0, 3))
    for p, n in ((pts, nrm), (empty, empty)):
        assert check.update(FSPFResult(points=p, normals=n, outliers=empty, plane_ids=np.zeros(len(p), np.int32))) is None
    assert check.evidence().frames_total == 0


def test_floor_fit_ignores_furniture_tops() -> None:
    """A big low table top in view does not pull the floor up or tilt it."""
    table = Scene(wall_m=4.5, boxes=((1.3, 3.0, -1.5, 0.2, 0.45),))
    depth = render(table, NOMINAL.pitch_down_rad, 0.0)
    res = fspf(depth, INTR, FSPFConfig(), seed=3, mount=NOMINAL)
    tops = (res.normals[:, 2] > 0.99) & (np.abs(res.points[:, 2] - 0.45) < 0.02)
    assert tops.sum() > 200
    fit = floor_fit(res.points, res.normals, NOMINAL, MountCheckConfig())
    assert fit is not None
    assert abs(fit.height_m - NOMINAL.height_m) < 0.005
    assert math.degrees(math.acos(fit.up @ NOMINAL.rotation()[2])) < 0.1


def test_tilted_camera_mount_matches_the_independent_axes() -> None:
    m = TiltedCameraMount(pitch_down_rad=0.4, roll_rad=-0.2)
    np.testing.assert_allclose(m.rotation(), np.column_stack(camera_axes(0.4, -0.2)), atol=1e-12)
    np.testing.assert_allclose(TiltedCameraMount().rotation(), CameraMount().rotation(), atol=1e-15)


def test_second_bump_is_corrected_again() -> None:
    """After a correction the estimate follows a further bump (forgetting the old floor)."""
    check = MountCheck(NOMINAL)
    p1 = NOMINAL.pitch_down_rad + math.radians(2.0)
    first = run(check, frames(p1, 0.0, 30))
    assert len(first) == 1
    p2, r2 = p1 - math.radians(3.0), math.radians(1.5)
    second = run(check, frames(p2, r2, 150, seed0=100), seed0=100)
    assert len(second) >= 1
    last = second[-1][1]
    assert math.degrees(abs(last.pitch_down_rad - p2)) < 0.3 and math.degrees(abs(last.roll_rad - r2)) < 0.3
    assert check.tilt_error_deg < 0.5


def test_the_correction_event_records_the_mount_in_degrees() -> None:
    """The event-log record of a corrected mount: time, pitch and roll rounded; the tilt
    error that made the correction (NaN before any); a plain mount has no roll."""
    check = MountCheck(NOMINAL)
    ev = check.correction_event(3.14159, TiltedCameraMount(pitch_down_rad=math.radians(12.3), roll_rad=math.radians(-1.5)))
    assert list(ev) == ["t", "event", "tilt_error_deg", "pitch_down_deg", "roll_deg"]
    assert (ev["t"], ev["event"], ev["pitch_down_deg"], ev["roll_deg"]) == (3.142, "mount corrected", 12.3, -1.5)
    assert math.isnan(ev["tilt_error_deg"])
    assert check.correction_event(0.0, NOMINAL)["roll_deg"] == 0.0


def test_config_errors_name_the_argument() -> None:
    with pytest.raises(InputError, match="mount_check.threshold_deg"):
        MountCheckConfig(threshold_deg=0.0)
    with pytest.raises(InputError, match="mount_check.window_frames"):
        MountCheckConfig(window_frames=0)
    with pytest.raises(InputError, match="mount: expected a CameraMount"):
        MountCheck("nominal")  # type: ignore[arg-type]


def _mujoco_run(mount: CameraMount, poses, frames_per_pose: int = 4) -> MountCheck:
    """The check fed FSPF (nominal mount) on noisy frames of the real renderer: a room
    with furniture, the robot at ``poses``, the camera really on ``mount``."""
    from sim.simulator.actors import Furniture
    from sim.simulator.kinect import KinectCamera, KinectConfig
    from sim.simulator.world import build_world
    from tests.helpers import box_room

    furniture = (
        Furniture("table", 6.0, 1.5), Furniture("chair", 4.5, 4.0), Furniture("box", 7.5, 4.5),
        Furniture("chair", 2.5, 1.2, 0.5), Furniture("cabinet", 9.3, 3.0),
    )
    w = build_world(box_room(), mount=mount, furniture=furniture)
    cam = KinectCamera(w.model, w.camera_id, KinectConfig(mount=mount))
    check = MountCheck(NOMINAL)
    try:
        k = 0
        for pose in poses:
            w.reset(pose)
            for _ in range(frames_per_pose):
                check.update(fspf(cam.capture(w.data, seed=k), INTR, FSPFConfig(), seed=k, mount=check.mount))
                k += 1
    finally:
        cam.close()
    return check


MUJOCO_POSES = [(x, y, th) for x, y in ((2.0, 3.0), (4.0, 2.0), (6.5, 3.5), (8.0, 1.5)) for th in (-2.0, -0.3, 0.6, 2.4)]


@pytest.mark.slow
@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_real_renderer_tilt_found_and_correct_mount_left_alone() -> None:
    """The same through MuJoCo's depth and the Kinect model, furniture included."""
    tilted = TiltedCameraMount(pitch_down_rad=NOMINAL.pitch_down_rad + math.radians(2.5), roll_rad=math.radians(-2.0))
    check = _mujoco_run(tilted, MUJOCO_POSES)
    ev = check.evidence()
    assert ev.corrections == 1 and isinstance(check.mount, TiltedCameraMount)
    assert math.degrees(abs(check.mount.pitch_down_rad - tilted.pitch_down_rad)) < 0.3
    assert math.degrees(abs(check.mount.roll_rad - tilted.roll_rad)) < 0.3
    assert abs(check.mount.height_m - tilted.height_m) < 0.02
    level = _mujoco_run(NOMINAL, MUJOCO_POSES)
    ev = level.evidence()
    assert ev.corrections == 0 and ev.frames_total > 40 and ev.tilt_deg < 0.3
