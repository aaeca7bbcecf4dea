"""Depth rendering through a headless OpenGL context: MuJoCo's depth buffer of the
``kinect`` camera as planar depth in metres (background -> 0), converted in one numba pass.

:class:`GLDepth` runs in the process that creates it; :mod:`sim.simulator.render_process`
hosts it in a render server process instead, and :mod:`sim.simulator.kinect` chooses.
Importing this module does not load the GL stack: the context is made on first use.
"""

from __future__ import annotations

import math

import mujoco
import numba
import numpy as np

from autonomy.common.errors import InputError
from autonomy.perception.camera import CameraIntrinsics
from sim.simulator.robot import ROBOT_GEOM_GROUP


@numba.njit(cache=True)
def _linearize_flip(raw, c_coef, d_coef, out):  # pragma: no cover - numba
    """Reversed-Z window depth -> planar metres, flipped to image row order; far -> 0."""
    h, w = raw.shape
    for v in range(h):
        src = raw[h - 1 - v]
        for u in range(w):
            r = src[u]
            if r <= 0.0:
                out[v, u] = 0.0
            else:
                out[v, u] = np.float32(d_coef / (np.float64(r) + c_coef))


def culled_geoms(geoms: np.ndarray, radii: np.ndarray, data: mujoco.MjData, camera_id: int, far_m: float) -> np.ndarray:
    """The ``geoms`` whose bounding sphere (``radii``) lies wholly beyond ``far_m`` or
    behind the camera (planar depth along the optical axis): nothing of them can show."""
    fwd = -data.cam_xmat[camera_id].reshape(3, 3)[:, 2]
    z = (data.geom_xpos[geoms] - data.cam_xpos[camera_id]) @ fwd
    return geoms[(z - radii > far_m) | (z + radii < 0.0)]


def static_geoms(model: mujoco.MjModel) -> np.ndarray:
    """Geoms on the world body (walls) that may be culled: not the floor plane, not the
    robot's own."""
    static = (model.geom_bodyid == 0) & (model.geom_type != mujoco.mjtGeom.mjGEOM_PLANE) & (model.geom_group != ROBOT_GEOM_GROUP)
    return np.flatnonzero(static)


class GLDepth:
    """Depth rendering through a headless OpenGL context (EGL / OSMesa / GLFW).

    Only the depth buffer is read back; lights, shadows, reflections, skybox and fog are
    off, and MSAA is off in the model (a resolved multisample depth buffer holds one
    sub-sample, ~0.4 px off the pixel centre).
    """

    def __init__(self, model: mujoco.MjModel, camera_id: int, intr: CameraIntrinsics, far_m: float = math.inf) -> None:
        from mujoco import gl_context

        if gl_context.GLContext is None:
            raise RuntimeError("no OpenGL context class available")
        self.model = model
        self.camera_id = camera_id
        self.intr = intr
        self._ctx = gl_context.GLContext(intr.width, intr.height)
        self._ctx.make_current()
        self._con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100.value)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._con)
        self._con.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(model, maxgeom=model.ngeom + 100)
        for flag in ("mjRND_SHADOW", "mjRND_REFLECTION", "mjRND_SKYBOX", "mjRND_FOG", "mjRND_HAZE"):
            self._scene.flags[getattr(mujoco.mjtRndFlag, flag)] = False
        self._opt = mujoco.MjvOption()
        self._opt.geomgroup[ROBOT_GEOM_GROUP] = 0
        self._cam = mujoco.MjvCamera()
        self._cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._cam.fixedcamid = camera_id
        self._rect = mujoco.MjrRect(0, 0, intr.width, intr.height)
        self._raw = np.empty((intr.height, intr.width), dtype=np.float32)
        extent = model.stat.extent
        near = np.float32(model.vis.map.znear * extent)
        far = np.float32(model.vis.map.zfar * extent)
        # A nearer far plane (the scene cameras' frustum, set each frame) clips what the
        # sensor cannot see anyway; the linearisation below follows it.
        self._far = None
        if math.isfinite(far_m) and np.float32(far_m) < far:
            if not np.float32(far_m) > near:
                raise InputError(f"kinect.render_far_m {far_m!r}: expected more than the near plane ({float(near):.3f} m)")
            far = self._far = np.float32(far_m)
        # Static geoms (walls) that may be culled: a thousand draw calls of walls beyond the
        # far plane or behind the camera still cost the CPU rasteriser ~1.5 ms a frame.
        self._static = static_geoms(model) if self._far is not None else np.zeros(0, dtype=np.int64)
        self._static_r = model.geom_rbound[self._static].copy()
        c = -(far + near) / (far - near)
        d = -(np.float32(2) * far * near) / (far - near)
        # Reversed-Z projection, as mujoco.Renderer undoes it.
        self._c = float(np.float32(-0.5) * c - np.float32(0.5))
        self._d = float(np.float32(-0.5) * d)

    def render(self, data: mujoco.MjData, out: np.ndarray | None = None) -> np.ndarray:
        """Clean planar depth (float32, metres, 0 = background)."""
        if out is None:
            out = np.empty((self.intr.height, self.intr.width), dtype=np.float32)
        self._ctx.make_current()
        cull = self._culled(data)
        if len(cull):
            # Hidden for this scene update only (the robot's group is not drawn).
            groups = self.model.geom_group[cull].copy()
            self.model.geom_group[cull] = ROBOT_GEOM_GROUP
        try:
            mujoco.mjv_updateScene(
                self.model, data, self._opt, None, self._cam, mujoco.mjtCatBit.mjCAT_ALL.value, self._scene
            )
        finally:
            if len(cull):
                self.model.geom_group[cull] = groups
        self._scene.nlight = 0  # depth needs no lighting; it costs the CPU rasteriser most
        if self._far is not None:
            for glcam in self._scene.camera:
                glcam.frustum_far = float(self._far)
        mujoco.mjr_render(self._rect, self._scene, self._con)
        mujoco.mjr_readPixels(None, self._raw, self._rect, self._con)
        _linearize_flip(self._raw, self._c, self._d, out)
        return out

    def _culled(self, data: mujoco.MjData) -> np.ndarray:
        if not len(self._static):
            return self._static
        return culled_geoms(self._static, self._static_r, data, self.camera_id, float(self._far))

    def close(self) -> None:
        if self._con is not None:
            self._ctx.make_current()
            self._con.free()
            self._con = None
        if self._ctx is not None:
            self._ctx.free()
            self._ctx = None

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass
