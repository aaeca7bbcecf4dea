"""Active localization: which exploring drive tells the relocalization's modes apart.

An undecided relocalization keeps several modes: poses that explain the scan about
equally well (two stretches of corridor alike, offices that mirror each other). The
robot drives on the best mode's plan; whichever mode is true, the robot then moves by
the same motion *relative to where it is*. Each mode therefore predicts what the camera
will see on the way: the plan's viewpoints, carried into that mode's frame, and the
ranges the map gives from there. Where two modes predict different ranges, the drive's
frames will explain one of them worse than the other.

A drive is worth the pairs of modes it tells apart: for each pair, the fraction of
predicted rays whose ranges differ by more than ``differ_m``, counted as one whole pair
once it reaches ``told_apart``. This is active Markov localization's idea (Fox1998:
choose the motion whose observations tell the hypotheses apart), scored by ray casting
instead of expected entropy, since the modes are few and the map is exact.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from autonomy.common.errors import InputError, require_positive
from autonomy.common.geometry import compose_pose, relative_pose
from autonomy.maps.raycast import rays_hit


@dataclass(frozen=True)
class ActiveLocalizationConfig:
    """How exploring drives are compared (ours; not from the papers)."""

    enabled: bool = True
    """Choose the drive that tells the modes apart (False: the one most nearly ahead)."""
    modes: int = 5
    """At most this many modes, best first, are compared ..."""
    score_margin: float = 0.1
    """... each scoring at most this much more than the best."""
    step_m: float = 1.0
    """Viewpoints along the drive's plan, this far apart."""
    drive_rays: int = 9
    """Rays across the camera's field of view at each viewpoint on the way ..."""
    look_rays: int = 36
    """... and all round at the drive's end, where the robot looks round."""
    differ_m: float = 0.5
    """Two modes predict a ray differently when its ranges differ by more than this
    (the scan's points are placed by dead reckoning: a few tenths of a metre off)."""
    told_apart: float = 0.1
    """A pair of modes is told apart when this fraction of the rays differ."""
    abandon_margin: float = 0.02
    """A drive goes on while the mode it set out on scores within this of the best mode
    (the per-point margin by which a mode is accepted over the others); past it, the
    robot sets out at once on the best mode instead."""

    def __post_init__(self) -> None:
        require_positive(self, "recovery.active.", "modes", "step_m", "drive_rays", "look_rays", "differ_m", "told_apart")
        for name in ("score_margin", "abandon_margin"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise InputError(f"recovery.active.{name}: expected a number >= 0, got {v!r}")


def view_poses(path: np.ndarray, length_m: float, step_m: float) -> np.ndarray:
    """Poses (V, 3) every ``step_m`` along the polyline ``path`` (K, 2) from its start
    up to ``length_m`` (or its end), each facing along the path; the last is where the
    path is cut. A path of one point gives no viewpoint."""
    p = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    seg = np.diff(p, axis=0)
    lengths = np.hypot(seg[:, 0], seg[:, 1])
    keep = lengths > 1e-9
    p0, seg, lengths = p[:-1][keep], seg[keep], lengths[keep]
    if not len(lengths):
        return np.zeros((0, 3))
    cum = np.concatenate([[0.0], np.cumsum(lengths)])
    end = min(float(length_m), float(cum[-1]))
    s = np.arange(0.0, end, step_m)
    s = np.append(s, end) if (not len(s) or end - s[-1] > 1e-6) else s
    k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(lengths) - 1)
    f = ((s - cum[k]) / lengths[k])[:, None]
    xy = p0[k] + f * seg[k]
    th = np.arctan2(seg[k, 1], seg[k, 0])
    return np.column_stack([xy, th])


def predicted_ranges(
    scene_lines: Callable[[float, float], np.ndarray], poses: np.ndarray, angles: np.ndarray, max_range_m: float
) -> np.ndarray:
    """Ranges (V, R) the map gives from each pose (V, 3) along each ray ``angles`` (R,)
    relative to its heading, capped at ``max_range_m`` (nothing hit: the cap)."""
    out = np.full((len(poses), len(angles)), float(max_range_m))
    for v, (x, y, th) in enumerate(np.asarray(poses, dtype=np.float64)):
        lines = np.ascontiguousarray(scene_lines(float(x), float(y)), dtype=np.float64).reshape(-1, 4)
        if not len(lines):
            continue
        a = th + angles
        _, t = rays_hit(lines, x, y, np.column_stack([np.cos(a), np.sin(a)]))
        out[v] = np.minimum(t, max_range_m)
    return out


def drive_value(
    scene_lines: Callable[[float, float], np.ndarray],
    path: np.ndarray,
    mode_poses: np.ndarray,
    cfg: ActiveLocalizationConfig,
    length_m: float,
    fov_rad: float,
    max_range_m: float,
) -> float:
    """How many pairs of modes a drive along ``path`` (K, 2; planned on the first mode's
    map from its pose) tells apart, each pair counting up to 1 (see the module's
    docstring). ``mode_poses`` (M, 3): the modes' poses now, the first the one the plan
    was made on. The drive stops after ``length_m`` and the robot looks round there."""
    modes = np.asarray(mode_poses, dtype=np.float64).reshape(-1, 3)
    if len(modes) < 2:
        return 0.0
    views = view_poses(path, length_m, cfg.step_m)
    if not len(views):
        return 0.0
    # The drive as motion relative to where the robot is: the same in every mode.
    rel = [relative_pose(modes[0], v) for v in views]
    half = 0.5 * fov_rad
    drive = np.linspace(-half, half, cfg.drive_rays) if cfg.drive_rays > 1 else np.zeros(1)
    look = np.linspace(-math.pi, math.pi, cfg.look_rays, endpoint=False)
    ranges = []
    for m in modes:
        here = np.array([compose_pose(m, r) for r in rel])
        on_way = predicted_ranges(scene_lines, here, drive, max_range_m).ravel()
        at_end = predicted_ranges(scene_lines, here[-1:], look, max_range_m).ravel()
        ranges.append(np.concatenate([on_way, at_end]))
    r = np.array(ranges)
    value = 0.0
    for i in range(len(r)):
        differ = np.mean(np.abs(r[i + 1 :] - r[i]) > cfg.differ_m, axis=1)
        value += float(np.minimum(differ / cfg.told_apart, 1.0).sum())
    return value
