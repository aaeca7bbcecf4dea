"""Pinhole depth-camera model: intrinsics, back-projection, and the robot mount.

Frames (docs/architecture.md, REP-103): the robot frame is x forward, y left, z up, origin on the
floor under the base centre. The camera *optical* frame is x right, y down, z forward.
Depth images are planar depth (distance along the optical axis) in float32 metres, with
0.0 marking invalid pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numba
import numpy as np

from autonomy.common.constants import KINECT_FOCAL_PX, KINECT_MAX_RANGE_M, KINECT_MIN_RANGE_M
from autonomy.common.errors import InputError, require_positive

#: Rotation taking optical-frame vectors (x right, y down, z forward) to a level
#: robot-style frame (x forward, y left, z up).
ROBOT_FROM_OPTICAL_LEVEL = np.array(
    [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]], dtype=np.float64
)


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of a depth image.

    The Kinect v1 depth camera is 640 x 480 with square pixels and f ~ 580 px (docs/architecture.md).
    With square pixels that gives a 57.8 x 44.9 degree field of view, the closest honest
    reading of the data sheet's 57 x 43 degrees.
    """

    width: int = 640
    """Image width in pixels."""
    height: int = 480
    """Image height in pixels."""
    fx: float = KINECT_FOCAL_PX
    """Focal length along x in pixels."""
    fy: float = KINECT_FOCAL_PX
    """Focal length along y in pixels."""
    cx: float = 319.5
    """Principal point x (pixel-centre coordinates: the first pixel's centre is 0)."""
    cy: float = 239.5
    """Principal point y."""

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise InputError(f"camera: width and height must be positive, got {self.width}x{self.height}")
        if not (self.fx > 0 and self.fy > 0):
            raise InputError(f"camera: fx and fy must be positive, got fx={self.fx}, fy={self.fy}")

    @property
    def fov_h_rad(self) -> float:
        """Horizontal field of view."""
        return 2.0 * math.atan(self.width / (2.0 * self.fx))

    @property
    def fov_v_rad(self) -> float:
        """Vertical field of view."""
        return 2.0 * math.atan(self.height / (2.0 * self.fy))

    def scaled(self, width: int, height: int) -> CameraIntrinsics:
        """The same camera at another resolution (e.g. a downsampled depth image)."""
        sx, sy = width / self.width, height / self.height
        return replace(
            self,
            width=width,
            height=height,
            fx=self.fx * sx,
            fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5,
            cy=(self.cy + 0.5) * sy - 0.5,
        )

    def matrix(self) -> np.ndarray:
        """The 3 x 3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class CameraMount:
    """Where the camera sits on the robot (CoBot-style defaults, docs/architecture.md)."""

    height_m: float = 0.7
    """Optical centre height above the floor."""
    forward_m: float = 0.22
    """Optical centre ahead of the base centre."""
    lateral_m: float = 0.0
    """Optical centre left of the base centre."""
    pitch_down_rad: float = math.radians(17.0)
    """Downward pitch of the optical axis."""

    def rotation(self) -> np.ndarray:
        """Rotation robot_from_optical (3 x 3)."""
        c, s = math.cos(self.pitch_down_rad), math.sin(self.pitch_down_rad)
        # Positive rotation about the robot's y axis tips x forward towards -z (down).
        r_y = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
        return r_y @ ROBOT_FROM_OPTICAL_LEVEL

    def translation(self) -> np.ndarray:
        """Optical centre in the robot frame (3,)."""
        return np.array([self.forward_m, self.lateral_m, self.height_m])

    def robot_from_camera(self) -> np.ndarray:
        """Homogeneous 4 x 4 transform robot_from_camera (optical frame)."""
        t = np.eye(4)
        t[:3, :3] = self.rotation()
        t[:3, 3] = self.translation()
        return t


@dataclass(frozen=True)
class DepthCamera:
    """The depth camera as the robot-side stack knows it: intrinsics, mount, valid range."""

    intrinsics: CameraIntrinsics = field(default_factory=CameraIntrinsics)
    """Pinhole intrinsics of the depth image."""
    mount: CameraMount = field(default_factory=CameraMount)
    """Where the camera sits on the robot."""
    min_range_m: float = KINECT_MIN_RANGE_M
    """Nothing closer than this is measured."""
    max_range_m: float = KINECT_MAX_RANGE_M
    """Nor anything farther than this."""

    def __post_init__(self) -> None:
        if not isinstance(self.intrinsics, CameraIntrinsics):
            raise InputError(f"camera.intrinsics: expected CameraIntrinsics, got {type(self.intrinsics).__name__}")
        if not isinstance(self.mount, CameraMount):
            raise InputError(f"camera.mount: expected CameraMount, got {type(self.mount).__name__}")
        require_positive(self, "camera.", "min_range_m")
        hi = self.max_range_m
        if isinstance(hi, bool) or not (isinstance(hi, (int, float)) and hi > self.min_range_m):
            raise InputError(f"camera.max_range_m: expected a number above min_range_m ({self.min_range_m!r}), got {hi!r}")

    @property
    def fov_h_rad(self) -> float:
        """Horizontal field of view (from the intrinsics)."""
        return self.intrinsics.fov_h_rad

    @property
    def forward_m(self) -> float:
        """Optical centre ahead of the base centre (from the mount)."""
        return float(self.mount.translation()[0])


KINECT_V1 = DepthCamera()
"""The Kinect v1 on the CoBot-style mount: every default above (a default argument)."""


@numba.njit(cache=True)
def _backproject(depth, fx, fy, cx, cy, out):  # pragma: no cover - numba
    h, w = depth.shape
    for v in range(h):
        for u in range(w):
            z = depth[v, u]
            out[v, u, 0] = (u - cx) * z / fx
            out[v, u, 1] = (v - cy) * z / fy
            out[v, u, 2] = z


def backproject(depth: np.ndarray, intr: CameraIntrinsics) -> np.ndarray:
    """Back-project a planar depth image to optical-frame points, shape (H, W, 3).

    Invalid pixels (depth 0) map to the origin; mask them with ``depth > 0``.
    """
    depth = np.ascontiguousarray(depth, dtype=np.float32)
    if depth.shape != (intr.height, intr.width):
        raise InputError(
            f"depth image shape {depth.shape} does not match the camera's {(intr.height, intr.width)}"
        )
    out = np.empty(depth.shape + (3,), dtype=np.float64)
    _backproject(depth, intr.fx, intr.fy, intr.cx, intr.cy, out)
    return out


@numba.njit(cache=True, inline="always")
def pixel_point_nb(u, v, z, fx, fy, cx, cy, rot, trans):  # pragma: no cover - numba
    """Pixel (u, v) at planar depth z, back-projected and moved through ``rot``,
    ``trans`` (a camera-to-robot transform's parts): (x, y, z)."""
    x = (u - cx) / fx * z
    y = (v - cy) / fy * z
    return (
        rot[0, 0] * x + rot[0, 1] * y + rot[0, 2] * z + trans[0],
        rot[1, 0] * x + rot[1, 1] * y + rot[1, 2] * z + trans[1],
        rot[2, 0] * x + rot[2, 1] * y + rot[2, 2] * z + trans[2],
    )


@numba.njit(cache=True)
def _frame_checks(flat, stride, last):  # pragma: no cover - numba
    valid = False
    for i in range(flat.size):
        v = flat[i]
        if v > 0.0 and v < np.inf:
            valid = True
            break
    n = (flat.size + stride - 1) // stride
    same = last.size == n
    if same:
        for k in range(n):
            if flat[k * stride] != last[k]:
                same = False
                break
    return valid, same


def frame_checks(depth: np.ndarray, stride: int, last_key: np.ndarray | None) -> tuple[bool, bool]:
    """(any finite positive pixel, the pixels every ``stride`` of the flattened frame equal
    ``last_key``) of a depth image; both stop at the first pixel that decides them."""
    flat = np.ascontiguousarray(depth).ravel()
    last = np.zeros(0, dtype=flat.dtype) if last_key is None else np.ascontiguousarray(last_key, dtype=flat.dtype)
    valid, same = _frame_checks(flat, int(stride), last)
    return bool(valid), bool(same) and last_key is not None


def pixel_rays(intr: CameraIntrinsics) -> np.ndarray:
    """Optical-frame ray directions with unit z for every pixel, shape (H, W, 3)."""
    u = (np.arange(intr.width) - intr.cx) / intr.fx
    v = (np.arange(intr.height) - intr.cy) / intr.fy
    rays = np.empty((intr.height, intr.width, 3))
    rays[..., 0] = u[None, :]
    rays[..., 1] = v[:, None]
    rays[..., 2] = 1.0
    return rays


def transform_points(t: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Apply a 4 x 4 homogeneous transform to an (..., 3) array of points."""
    return pts @ t[:3, :3].T + t[:3, 3]
