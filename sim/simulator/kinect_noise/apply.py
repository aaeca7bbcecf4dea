"""The public entry points: :func:`apply_kinect_noise` and :func:`incidence_angle`."""

from __future__ import annotations

import functools
import math

import numpy as np

from autonomy.common.errors import InputError
from autonomy.perception.camera import CameraIntrinsics
from sim.simulator.kinect_noise.blocks import CPUS, run_blocks
from sim.simulator.kinect_noise.config import KinectNoiseConfig
from sim.simulator.kinect_noise.draws import LAT_G_MAX, check_seed, field_key, seed_key
from sim.simulator.kinect_noise.fields import (
    field_arg,
    no_field,
    no_pattern,
    pattern_image,
    pattern_on,
)
from sim.simulator.kinect_noise.geometry import Q_MAX
from sim.simulator.kinect_noise.kernels import block


def _check_depth(depth, intr: CameraIntrinsics) -> np.ndarray:
    """The depth image as C-contiguous float32, or InputError naming what is wrong."""
    if not isinstance(intr, CameraIntrinsics):
        raise InputError(f"intrinsics: expected CameraIntrinsics, got {type(intr).__name__}")
    arr = np.asarray(depth)
    if arr.dtype.kind != "f":
        raise InputError(f"depth image: expected a float array in metres, got dtype {arr.dtype}")
    if arr.shape != (intr.height, intr.width):
        raise InputError(
            f"depth image shape {arr.shape} does not match the camera's {(intr.height, intr.width)}"
        )
    return np.ascontiguousarray(arr, dtype=np.float32)


@functools.lru_cache(maxsize=8)
def _normalised_coords(intr: CameraIntrinsics) -> tuple[np.ndarray, np.ndarray]:
    """float32 (u - cx) / fx and (v - cy) / fy (cached per camera; read-only)."""
    xn = ((np.arange(intr.width, dtype=np.float64) - intr.cx) / intr.fx).astype(np.float32)
    yn = ((np.arange(intr.height, dtype=np.float64) - intr.cy) / intr.fy).astype(np.float32)
    xn.setflags(write=False)
    yn.setflags(write=False)
    return xn, yn


def incidence_angle(
    depth: np.ndarray, intr: CameraIntrinsics, max_rel_jump: float = 0.05
) -> np.ndarray:
    """Angle between each pixel's ray and its surface normal (float32 radians, H x W).

    Normals are the cross product of horizontal and vertical differences of back-projected
    neighbours (central; one-sided at borders, invalid neighbours and depth jumps larger
    than ``max_rel_jump * z``). Pixels without a normal (or invalid) get 0.
    """
    d = _check_depth(depth, intr)
    if not (isinstance(max_rel_jump, int | float) and max_rel_jump > 0):
        raise InputError(f"incidence_angle: max_rel_jump must be > 0, got {max_rel_jump!r}")
    xn, yn = _normalised_coords(intr)
    theta = np.empty(d.shape, dtype=np.float32)
    lat, axl, drop = _cfg_arrays(KinectNoiseConfig(), intr)
    t = theta
    f0 = np.float32(0)
    block(
        d, 0, d.shape[0], 0, xn, yn, np.float32(max_rel_jump), lat, f0, np.uint64(0), axl,
        drop, False, f0, f0, f0, no_field(d.shape), no_pattern(), t, t, t, t, True,
    )  # fmt: skip
    return theta


def _fbs(cfg: KinectNoiseConfig) -> float:
    """subpixel * focal_px * baseline_m: depth times disparity in 1/subpixel px units."""
    return float(cfg.subpixel) * float(cfg.focal_px) * float(cfg.baseline_m)


@functools.lru_cache(maxsize=32)
def _cfg_arrays(cfg: KinectNoiseConfig, intr: CameraIntrinsics) -> tuple[np.ndarray, ...]:
    """The kernel's float32 parameter vectors (lateral, axial, dropouts) of a config and camera."""
    f32 = np.float32
    lat = np.array(
        [cfg.lateral, cfg.lateral_a_px, cfg.lateral_b_px, intr.fx / cfg.focal_px], dtype=f32
    )
    axl = np.array(
        [cfg.axial, cfg.axial_a_m, cfg.axial_b_per_m, cfg.axial_z0_m, cfg.axial_grazing_m,
         cfg.axial_grazing_start_rad],
        dtype=f32,
    )  # fmt: skip
    drop = np.array(
        [cfg.dropouts, cfg.dropout_start_rad, 1.0 / (cfg.dropout_full_rad - cfg.dropout_start_rad),
         cfg.dropout_rate if cfg.dropouts else 0.0],
        dtype=f32,
    )  # fmt: skip
    return lat, axl, drop


def apply_kinect_noise(
    depth: np.ndarray,
    intr: CameraIntrinsics,
    cfg: KinectNoiseConfig,
    seed: int,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """The noisy Kinect v1 depth image (float32 metres, 0 = invalid) for a clean planar depth.

    ``out`` (float32, C-contiguous, H x W) is filled and returned if given; it may be the
    input array itself. Same seed -> identical output. Pixels invalid in the input (0,
    negative, NaN, inf) are 0 in the output.
    """
    d = _check_depth(depth, intr)
    if not isinstance(cfg, KinectNoiseConfig):
        raise InputError(f"cfg: expected KinectNoiseConfig, got {type(cfg).__name__}")
    key = seed_key(check_seed(seed))
    if out is None:
        out = np.empty(d.shape, dtype=np.float32)
    elif not (
        isinstance(out, np.ndarray)
        and out.dtype == np.float32
        and out.shape == d.shape
        and out.flags.c_contiguous
        and out.flags.writeable
    ):
        raise InputError(f"out: expected a writeable C-contiguous float32 array of shape {d.shape}")
    if np.shares_memory(d, out):
        d = d.copy()
    xn, yn = _normalised_coords(intr)
    lat, axl, drop = _cfg_arrays(cfg, intr)
    # bound on |lateral row offset|: the largest table normal times the largest sigma_L
    sigma_max = float(lat[0]) * float(lat[3]) * (float(lat[1]) + float(lat[2]) * Q_MAX)
    margin = math.ceil(LAT_G_MAX * sigma_max) + 1
    n = max(1, min(cfg.threads, CPUS, d.shape[0]))
    h, w = d.shape
    scale = intr.fx / cfg.focal_px  # correlation lengths are in px of the focal_px camera
    if cfg.correlated and cfg.axial:
        fld = field_arg(field_key(key, 1), h, w, cfg.corr_length_px * scale)
    else:
        fld = no_field(d.shape)
    pat = (True, pattern_image(cfg, h, w, scale)) if pattern_on(cfg) else no_pattern()
    args = (
        xn, yn, np.float32(cfg.normal_max_rel_jump), lat,
        np.float32(intr.fx * cfg.projector_offset_m if cfg.shadows else 0.0), key, axl, drop,
        bool(cfg.quantize), np.float32(_fbs(cfg)), np.float32(cfg.min_range_m),
        np.float32(cfg.max_range_m), fld, pat,
    )  # fmt: skip
    run_blocks(n, d, margin, args, out)
    return out
