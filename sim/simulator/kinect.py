"""The Kinect-model depth camera: MuJoCo depth rendering (EGL) or ray casting, plus noise.

Clean depth comes from the OpenGL depth buffer of the ``kinect`` camera (planar depth,
i.e. distance along the optical axis, in metres; background -> 0;
:class:`sim.simulator.gl_depth.GLDepth`). By default the GL stack runs in a render server
process (:mod:`sim.simulator.render_process`), so that Mesa's LLVM never loads into the
caller (where it would crash PyTorch's triton). Where no GL context can be made,
:class:`RaycastDepth` casts one ray per pixel with ``mujoco.mj_multiRay`` instead (same
geometry, same output, much slower). The noise model is :mod:`sim.simulator.kinect_noise`.
The robot's own geoms (group 3) are hidden.
"""

from __future__ import annotations

import math
import os
import time
import warnings
from dataclasses import dataclass, field

import mujoco
import numpy as np

from autonomy.common.errors import InputError
from autonomy.perception.camera import CameraIntrinsics, CameraMount, DepthCamera, pixel_rays
from sim.simulator.gl_depth import GLDepth
from sim.simulator.kinect_noise import KinectNoiseConfig, apply_kinect_noise
from sim.simulator.render_process import ProcessGLDepth
from sim.simulator.robot import ROBOT_GEOM_GROUP

BACKENDS = ("auto", "gl", "raycast")


RENDER_FAR_MARGIN_M = 1.0
"""Rendered depth beyond the noise model's range cut: axial noise and the lateral jitter
never bring a surface 1 m nearer, so the noisy frame does not change."""


@dataclass(frozen=True)
class KinectConfig:
    """The depth camera: intrinsics, mount, rate, noise and rendering backend."""

    intrinsics: CameraIntrinsics = field(default_factory=CameraIntrinsics)
    """Pinhole intrinsics (640 x 480, f = 580 px)."""
    mount: CameraMount = field(default_factory=CameraMount)
    """Pose on the robot (0.7 m high, 0.22 m forward, 17 deg down)."""
    rate_hz: float = 30.0
    """Frame rate."""
    noise: KinectNoiseConfig = field(default_factory=KinectNoiseConfig)
    """Noise model; every term switchable."""
    backend: str = "auto"
    """auto (GL if a context can be made, else ray casting), gl, or raycast."""
    render_process: bool = True
    """GL renders in a render server process, so Mesa (and its LLVM) never loads into
    this one: safe with PyTorch and triton imported before or after. False renders in
    this process (about 0.25 ms less a 640 x 480 frame; a later ``import triton`` then
    crashes, see docs/env.md)."""
    render_far_m: float = 0.0
    """Nothing farther than this is rendered: the clean depth is 0 beyond it. 0 = the noise
    model's ``max_range_m`` plus ``RENDER_FAR_MARGIN_M`` (the noise model returns nothing
    farther, so the noisy frame is the same but at ~0.01% of pixels; with the walls beyond
    it culled, 10.4 to 6.3 ms a frame over 40 poses in the building); inf = the model's
    own far plane."""

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise InputError(f"kinect.backend {self.backend!r}: expected one of {', '.join(BACKENDS)}")
        if not isinstance(self.render_process, bool):
            raise InputError(f"kinect.render_process: expected true or false, got {self.render_process!r}")
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise InputError(f"kinect.rate_hz: expected a positive number, got {self.rate_hz!r}")
        if not (self.render_far_m == 0 or self.render_far_m > self.noise.min_range_m):
            raise InputError(
                f"kinect.render_far_m: expected 0 (from the noise model's range) or more than "
                f"kinect.noise.min_range_m ({self.noise.min_range_m} m), got {self.render_far_m!r}"
            )

    def depth_camera(self) -> DepthCamera:
        """The camera as the robot-side stack knows it: the same intrinsics, mount and
        valid range (the noise model's), so the two cannot disagree."""
        lo, hi = float(self.noise.min_range_m), float(self.noise.max_range_m)
        if not lo > 0:
            # The noise model alone may return depth down to 0 m; a robot needs to know
            # what it cannot see (the near field reasons from that blind range).
            raise InputError(f"kinect.noise.min_range_m: expected a positive minimum range for the robot stack, got {lo!r}")
        return DepthCamera(self.intrinsics, self.mount, lo, hi)

    def far_m(self) -> float:
        """The render's far clipping distance in metres (inf = the model's own)."""
        if self.render_far_m > 0:
            return float(self.render_far_m)
        return float(self.noise.max_range_m) + RENDER_FAR_MARGIN_M


class RaycastDepth:
    """Depth by casting one ray per pixel with ``mujoco.mj_multiRay`` (no GL needed)."""

    def __init__(
        self, model: mujoco.MjModel, camera_id: int, intr: CameraIntrinsics, max_range_m: float = 20.0, far_m: float = math.inf
    ):
        self.model = model
        self.camera_id = camera_id
        self.intr = intr
        rays = pixel_rays(intr).reshape(-1, 3)
        self._norm = np.linalg.norm(rays, axis=1)
        # Rays stop at max_range_m, and at the far plane (a planar depth: rays to the image
        # corners are longer); beyond it the depth is 0, as the GL far plane clips.
        self.far_m = float(far_m)
        self.max_range_m = min(float(max_range_m), self.far_m * float(self._norm.max()))
        # Optical -> MuJoCo camera axes (y and z flipped), unit length.
        self._dirs_cam = (rays * np.array([1.0, -1.0, -1.0])) / self._norm[:, None]
        self._group = np.ones(6, dtype=np.uint8)
        self._group[ROBOT_GEOM_GROUP] = 0
        n = len(rays)
        self._geomid = np.empty(n, dtype=np.int32)
        self._dist = np.empty(n, dtype=np.float64)
        self._robot_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "robot")

    def render(self, data: mujoco.MjData, out: np.ndarray | None = None) -> np.ndarray:
        if out is None:
            out = np.empty((self.intr.height, self.intr.width), dtype=np.float32)
        rot = data.cam_xmat[self.camera_id].reshape(3, 3)
        pos = data.cam_xpos[self.camera_id].copy()
        vec = np.ascontiguousarray((self._dirs_cam @ rot.T).reshape(-1))
        mujoco.mj_multiRay(
            self.model,
            data,
            pos,
            vec,
            self._group,
            1,
            self._robot_body,
            self._geomid,
            self._dist,
            None,
            len(self._dist),
            self.max_range_m,
        )
        z = np.where(self._geomid >= 0, self._dist / self._norm, 0.0)
        if math.isfinite(self.far_m):
            z[z > self.far_m] = 0.0
        out[:] = z.reshape(out.shape)
        return out

    def close(self) -> None:
        pass


def make_depth_backend(
    model: mujoco.MjModel,
    camera_id: int,
    intr: CameraIntrinsics,
    backend: str = "auto",
    far_m: float = math.inf,
    process: bool = True,
):
    """The GL depth renderer (in the render server process, or with ``process=False`` in
    this one), or the ray-cast fallback when no GL context can be made; nothing farther
    than ``far_m`` is rendered (inf = the model's far plane)."""
    if backend not in BACKENDS:
        raise InputError(f"kinect.backend {backend!r}: expected one of {', '.join(BACKENDS)}")
    if backend in ("auto", "gl"):
        try:
            if process:
                return ProcessGLDepth(model, camera_id, intr, far_m)
            return GLDepth(model, camera_id, intr, far_m)
        except InputError:
            raise
        except Exception as exc:  # no EGL/OSMesa/display: fall back
            reason = f"OpenGL depth rendering unavailable (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): {exc}"
            if backend == "gl":
                raise RuntimeError(reason) from exc
            warnings.warn(f"{reason}; using the ray-cast depth fallback (much slower)", RuntimeWarning, stacklevel=2)
    return RaycastDepth(model, camera_id, intr, far_m=far_m)


class KinectCamera:
    """A simulated Kinect on a world's robot: ``capture`` gives the noisy depth frame.

    The renderer is created lazily on first use, so a camera can be built (and pickled
    with its owner) before any GL context exists.
    """

    def __init__(self, model: mujoco.MjModel, camera_id: int, cfg: KinectConfig) -> None:
        self.model = model
        self.camera_id = camera_id
        self.cfg = cfg
        self._backend = None
        self._clean = np.zeros((cfg.intrinsics.height, cfg.intrinsics.width), dtype=np.float32)
        self.last_render_s = 0.0
        self.last_noise_s = 0.0

    @property
    def backend_name(self) -> str:
        """'gl' (in the render process or this one) or 'raycast'."""
        return "raycast" if isinstance(self.backend, RaycastDepth) else "gl"

    @property
    def backend(self):
        if self._backend is None:
            self._backend = make_depth_backend(
                self.model, self.camera_id, self.cfg.intrinsics, self.cfg.backend, self.cfg.far_m(), self.cfg.render_process
            )
        return self._backend

    def render_clean(self, data: mujoco.MjData) -> np.ndarray:
        """Noise-free planar depth (a view of an internal buffer: copy to keep)."""
        return self.backend.render(data, self._clean)

    def capture(self, data: mujoco.MjData, seed: int, out: np.ndarray | None = None) -> np.ndarray:
        """A Kinect frame: clean render followed by the noise model, seeded. The seconds
        each took are kept in ``last_render_s`` and ``last_noise_s``."""
        t0 = time.perf_counter()
        clean = self.render_clean(data)
        t1 = time.perf_counter()
        depth = apply_kinect_noise(clean, self.cfg.intrinsics, self.cfg.noise, seed, out=out)
        self.last_render_s, self.last_noise_s = t1 - t0, time.perf_counter() - t1
        return depth

    def close(self) -> None:
        if self._backend is not None:
            self._backend.close()
            self._backend = None
