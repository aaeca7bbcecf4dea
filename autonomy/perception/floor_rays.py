"""How far the camera saw the floor: sight lines that no wall crosses.

FSPF keeps the planes the camera sees and leaves out the floor, so the relocalization's
scan (:mod:`autonomy.localization.relocalization`) holds walls, pillars and furniture, and says
nothing about where the camera saw far into open space. Yet a floor point seen 4 m away
says that no wall stands on the sight line to it: walls stand on the floor and reach
above the camera, so a wall in between would have hidden it (low furniture does not
matter here: the sight line passes over it). A place whose map puts a wall across such
a sight line is not where the robot is. In an open hall with furniture the map lacks,
the furniture's faces fit some office's walls elsewhere better than the hall's few
walls fit the hall; the office's walls then stand across the sight lines into the hall
(ours; the scan's sight through walls,
:meth:`autonomy.localization.relocalization.GlobalLocalizer.scan_through_at`, for the floor).

Each frame, in every ``stride_u_px``-th image column, the deepest pixel (on every
``stride_v_px``-th row from the bottom) whose back-projected point lies on the floor (height within
``tol_m + tol_per_m2 z^2`` of 0: the Kinect's noise grows with depth squared, and a
camera tilted by a degree or two raises far floor by a few centimetres) gives one floor
point, in the robot frame.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from autonomy.perception.camera import CameraIntrinsics, pixel_point_nb

__all__ = ["REACH_STRIDE_PX", "floor_rays", "floor_reach"]


def floor_rays(
    depth: np.ndarray, intr: CameraIntrinsics, robot_from_camera: np.ndarray, stride_u_px: int = 16, stride_v_px: int = 4,
    tol_m: float = 0.05, tol_per_m2: float = 0.01,
) -> np.ndarray:
    """Robot-frame (x, y) of the farthest floor point in each ``stride_u_px``-th column of
    ``depth`` (planar depth, 0 or non-finite = no return); columns that saw no floor give
    none (module docstring)."""
    far = _farthest_floor(depth, intr, robot_from_camera, stride_u_px, stride_v_px, tol_m, tol_per_m2)
    return far[far[:, 0] > 0.0, 1:].copy()


#: :func:`floor_reach` looks at every this-many-th column; column u's reach is entry
#: ``u // REACH_STRIDE_PX`` (the floor a few pixels aside is seen past the same things).
REACH_STRIDE_PX = 4


def floor_reach(
    depth: np.ndarray, intr: CameraIntrinsics, robot_from_camera: np.ndarray, stride_v_px: int = 4, tol_m: float = 0.05,
    tol_per_m2: float = 0.01,
) -> np.ndarray:
    """Per ``REACH_STRIDE_PX``-th image column, the largest planar depth at which it
    returned the floor (0: no floor in that column). Nothing stands in the column's view
    of the floor nearer than that: a wall 0.8 m ahead, whose upper part the camera sees
    too close to return, keeps it below 1 m."""
    return _farthest_floor(depth, intr, robot_from_camera, REACH_STRIDE_PX, stride_v_px, tol_m, tol_per_m2)[:, 0].copy()


def _farthest_floor(
    depth: np.ndarray, intr: CameraIntrinsics, robot_from_camera: np.ndarray, su: int, sv: int, tol_m: float, tol_q: float
) -> np.ndarray:
    """(planar depth, robot-frame x, y) of the deepest floor return in each ``su``-th
    column, on every ``sv``-th row from the bottom (depth 0: none)."""
    rc = np.ascontiguousarray(robot_from_camera, dtype=np.float64)
    d = np.ascontiguousarray(depth, dtype=np.float32)
    return _floor_kernel(
        d, int(su), int(sv), float(intr.fx), float(intr.fy), float(intr.cx), float(intr.cy), rc[:3, :3].copy(),
        rc[:3, 3].copy(), float(tol_m), float(tol_q),
    )


@numba.njit(cache=True)
def _floor_kernel(depth, su, sv, fx, fy, cx, cy, rot, trans, tol_m, tol_q):  # pragma: no cover - numba
    """:func:`_farthest_floor`, column by column. In one column the floor's planar depth
    grows with its distance, so the deepest floor return is the farthest."""
    h, w = depth.shape
    out = np.zeros(((w + su - 1) // su, 3))
    for k in range(out.shape[0]):
        u = k * su
        for v in range(h - 1, -1, -sv):
            z = depth[v, u]
            if not (z > 0.0) or not math.isfinite(z) or z <= out[k, 0]:
                continue
            px, py, pz = pixel_point_nb(u, v, z, fx, fy, cx, cy, rot, trans)
            if abs(pz) <= tol_m + tol_q * z * z:
                out[k, 0] = z
                out[k, 1] = px
                out[k, 2] = py
    return out
