"""The noise model's parameters (:class:`KinectNoiseConfig`) and its closed forms:
sigma_z, sigma_L, the disparity grid's depth step and the dropout probability."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from autonomy.common.constants import KINECT_FOCAL_PX, KINECT_MAX_RANGE_M, KINECT_MIN_RANGE_M
from autonomy.common.errors import InputError

#: Incidence angles are clamped below this in the closed forms (both blow up at pi/2).
THETA_MAX_RAD = math.radians(89.0)


@dataclass(frozen=True)
class KinectNoiseConfig:
    """Parameters of the Kinect v1 noise model (Nguyen, Izadi & Lovell 2012; docs/architecture.md)."""

    axial: bool = True
    """Add Gaussian axial noise sigma_z(z, theta)."""
    axial_a_m: float = 0.0012
    """Constant term of sigma_z (Nguyen et al.: 0.0012 m)."""
    axial_b_per_m: float = 0.0019
    """Quadratic coefficient of sigma_z in (z - z0)^2 (0.0019 1/m)."""
    axial_z0_m: float = 0.4
    """Depth z0 of the quadratic's vertex (0.4 m)."""
    axial_grazing_m: float = 0.0001
    """Grazing-term coefficient of sigma_z: c / sqrt(z) * theta^2 / (pi/2 - theta)^2 (0.0001)."""
    axial_grazing_start_rad: float = math.radians(60.0)
    """Incidence angle above which the grazing term is added (60 degrees)."""
    correlated: bool = True
    """Spatially correlated axial noise: the share qz^2 / (a^2 + qz^2) of sigma_z^2, with a
    its constant and qz = b (z - z0)^2 its range term, is a smooth random field; the rest
    stays per pixel. False: all of sigma_z is independent from pixel to pixel (the
    independent model)."""
    corr_length_px: float = 32.0
    """Correlation length L of that field (px of the focal_px camera): its autocorrelation
    is exp(-(r / L)^2)."""
    pattern: bool = True
    """Add the sensor's fixed disparity pattern: the same in every frame of a run."""
    pattern_sigma_px: float = 0.09
    """Standard deviation of the fixed pattern in disparity over the image (px of the
    focal_px camera); the pattern has zero mean."""
    pattern_length_px: float = 96.0
    """Correlation length of the fixed pattern (px of the focal_px camera)."""
    pattern_seed: int = 0
    """Which sensor: the seed of the fixed pattern (independent of the per-frame seed)."""
    lateral: bool = True
    """Jitter each pixel's source position by the lateral noise sigma_L(theta)."""
    lateral_a_px: float = 0.8
    """Constant term of sigma_L in pixels of the 580 px camera (0.8 px)."""
    lateral_b_px: float = 0.035
    """Coefficient of theta / (pi/2 - theta) in sigma_L (0.035 px)."""
    quantize: bool = True
    """Quantise the disparity d = f b / z to 1/subpixel px."""
    focal_px: float = KINECT_FOCAL_PX
    """Focal length f of the IR camera used for disparity (px)."""
    baseline_m: float = 0.075
    """Projector-camera baseline b used for disparity (m)."""
    subpixel: int = 8
    """Disparity steps per pixel (Kinect v1: 1/8 px)."""
    min_range_m: float = KINECT_MIN_RANGE_M
    """Measured depths below this become 0."""
    max_range_m: float = KINECT_MAX_RANGE_M
    """Measured depths above this become 0 (may be inf)."""
    shadows: bool = True
    """Zero the pixels the IR projector cannot see."""
    projector_offset_m: float = 0.075
    """Projector position along the optical x axis from the camera (+ = right in the image)."""
    dropouts: bool = True
    """Drop pixels seen at grazing incidence."""
    dropout_start_rad: float = math.radians(70.0)
    """Incidence angle where the dropout probability starts rising from 0."""
    dropout_full_rad: float = math.radians(85.0)
    """Incidence angle where the dropout probability reaches 1."""
    dropout_rate: float = 0.0
    """Extra uniform dropout probability for every valid pixel (when dropouts is on)."""
    normal_max_rel_jump: float = 0.05
    """Neighbour depth jump (relative to z) beyond which it is not used for the normal."""
    threads: int = 2
    """Threads for the kernels (capped at the CPU count); the output does not depend on it."""

    def __post_init__(self) -> None:
        self._check_types()
        self._check_ranges()

    def _check_types(self) -> None:
        """Bools are bools, ``subpixel`` and ``threads`` positive ints, ``pattern_seed`` an
        int in [0, 2**64), the rest finite numbers (``max_range_m`` may be inf)."""
        for fd in fields(self):
            val = getattr(self, fd.name)
            if fd.type in ("bool", bool):
                if not isinstance(val, bool | np.bool_):
                    raise InputError(f"KinectNoiseConfig.{fd.name}: expected a bool, got {val!r}")
            elif fd.name == "pattern_seed":
                if isinstance(val, bool) or not isinstance(val, int | np.integer) or not 0 <= val < 2**64:
                    raise InputError(f"KinectNoiseConfig.{fd.name}: expected an int in [0, 2**64), got {val!r}")
            elif fd.name in ("subpixel", "threads"):
                if isinstance(val, bool) or not isinstance(val, int | np.integer) or val <= 0:
                    raise InputError(
                        f"KinectNoiseConfig.{fd.name}: expected a positive int, got {val!r}"
                    )
            else:
                if isinstance(val, bool) or not isinstance(
                    val, int | float | np.integer | np.floating
                ):
                    raise InputError(f"KinectNoiseConfig.{fd.name}: expected a number, got {val!r}")
                if math.isnan(val) or (math.isinf(val) and fd.name != "max_range_m"):
                    raise InputError(f"KinectNoiseConfig.{fd.name}: must be finite, got {val!r}")

    def _check_ranges(self) -> None:
        def need(ok: bool, name: str, what: str) -> None:
            if not ok:
                raise InputError(f"KinectNoiseConfig.{name}: {what}, got {getattr(self, name)!r}")

        need(self.axial_a_m >= 0, "axial_a_m", "must be >= 0")
        need(self.axial_b_per_m >= 0, "axial_b_per_m", "must be >= 0")
        need(self.axial_grazing_m >= 0, "axial_grazing_m", "must be >= 0")
        need(
            0 <= self.axial_grazing_start_rad < math.pi / 2,
            "axial_grazing_start_rad",
            "must be in [0, pi/2)",
        )
        need(self.corr_length_px > 0, "corr_length_px", "must be > 0")
        need(self.pattern_sigma_px >= 0, "pattern_sigma_px", "must be >= 0")
        need(self.pattern_length_px > 0, "pattern_length_px", "must be > 0")
        need(self.lateral_a_px >= 0, "lateral_a_px", "must be >= 0")
        need(self.lateral_b_px >= 0, "lateral_b_px", "must be >= 0")
        need(self.focal_px > 0, "focal_px", "must be > 0")
        need(self.baseline_m > 0, "baseline_m", "must be > 0")
        need(self.min_range_m >= 0, "min_range_m", "must be >= 0")
        need(
            self.max_range_m > self.min_range_m,
            "max_range_m",
            f"must be > min_range_m={self.min_range_m}",
        )
        need(
            0 <= self.dropout_start_rad <= math.pi / 2, "dropout_start_rad", "must be in [0, pi/2]"
        )
        need(
            self.dropout_start_rad < self.dropout_full_rad <= math.pi / 2,
            "dropout_full_rad",
            f"must be in (dropout_start_rad={self.dropout_start_rad:.4f}, pi/2]",
        )
        need(0 <= self.dropout_rate <= 1, "dropout_rate", "must be in [0, 1]")
        need(self.normal_max_rel_jump > 0, "normal_max_rel_jump", "must be > 0")


# --------------------------------------------------------------------------- closed forms


def axial_sigma_m(z, theta, cfg: KinectNoiseConfig | None = None) -> np.ndarray:
    """Axial noise sigma_z(z, theta) in metres (Nguyen, Izadi & Lovell 2012, Sec. 3).

    0.0012 + 0.0019 (z - 0.4)^2, plus 0.0001 / sqrt(z) * theta^2 / (pi/2 - theta)^2 for
    theta > 60 degrees. theta is clamped to :data:`THETA_MAX_RAD`.
    """
    c = cfg or KinectNoiseConfig()
    z = np.asarray(z, dtype=np.float64)
    th = np.minimum(np.asarray(theta, dtype=np.float64), THETA_MAX_RAD)
    s = c.axial_a_m + c.axial_b_per_m * (z - c.axial_z0_m) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        graze = c.axial_grazing_m / np.sqrt(z) * th**2 / (math.pi / 2 - th) ** 2
    return np.where(th > c.axial_grazing_start_rad, s + graze, s)


def lateral_sigma_px(theta, cfg: KinectNoiseConfig | None = None) -> np.ndarray:
    """Lateral noise sigma_L(theta) = 0.8 + 0.035 theta / (pi/2 - theta) px (Nguyen et al. 2012).

    In pixels of a camera with ``cfg.focal_px``; theta is clamped to :data:`THETA_MAX_RAD`.
    """
    c = cfg or KinectNoiseConfig()
    th = np.minimum(np.asarray(theta, dtype=np.float64), THETA_MAX_RAD)
    return c.lateral_a_px + c.lateral_b_px * th / (math.pi / 2 - th)


def depth_step_m(z, cfg: KinectNoiseConfig | None = None) -> np.ndarray:
    """Depth spacing of the disparity grid at z, to first order z^2 / (subpixel f b).

    2.9 mm at 1 m and 46 mm at 4 m for the Kinect v1 defaults (docs/architecture.md).
    """
    c = cfg or KinectNoiseConfig()
    z = np.asarray(z, dtype=np.float64)
    return z * z / (c.subpixel * c.focal_px * c.baseline_m)


def dropout_probability(theta, cfg: KinectNoiseConfig | None = None) -> np.ndarray:
    """Grazing-angle dropout probability: linear from 0 at dropout_start_rad to 1 at dropout_full_rad."""
    c = cfg or KinectNoiseConfig()
    th = np.asarray(theta, dtype=np.float64)
    return np.clip(
        (th - c.dropout_start_rad) / (c.dropout_full_rad - c.dropout_start_rad), 0.0, 1.0
    )
