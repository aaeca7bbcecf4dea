"""GL depth rendering in a separate process, so the GL stack never loads into this one.

Mesa's software rasteriser (llvmpipe) brings its own LLVM, and Mesa's loader opens the
driver with ``RTLD_GLOBAL``: once a process has made an EGL context, LLVM's symbols are
global in it. A library loaded later that carries another LLVM and resolves its own
symbols through the global scope (triton, which PyTorch imports with ``torch._dynamo`` at
the first optimizer step) then binds to Mesa's copy and crashes in its static
initialisers. Rendering here, in a child started with ``python -m`` (not
``multiprocessing``, so a user's script without a ``__main__`` guard is never re-run),
keeps Mesa out of the caller's process whatever it imports, before or after.

One render server per process, started on first use, hosts every camera of that process
(a new building sends its model once). Per frame the caller writes the poses of the
moving geoms (everything not on the world body) and of the camera into a shared memory
file, sends one short message and waits; the server renders with
:class:`sim.simulator.gl_depth.GLDepth` into the same file. The server sees the very
``geom_xpos``/``geom_xmat``/``cam_xpos``/``cam_xmat`` the caller holds, so the frame is
the one an in-process render makes, bit for bit. A process forked from one that owns a
server starts its own on first use (the pipes belong to the parent).
"""

from __future__ import annotations

import atexit
import contextlib
import math
import mmap
import os
import pickle
import signal
import struct
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from autonomy.common.errors import InputError
from autonomy.perception.camera import CameraIntrinsics
from sim.simulator.gl_depth import GLDepth

_HEADER = struct.Struct("<I")


def _send(fd: int, obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    _write_all(fd, _HEADER.pack(len(data)) + data)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def _read_exact(fd: int, n: int) -> bytes:
    chunks, got = [], 0
    while got < n:
        b = os.read(fd, n - got)
        if not b:
            raise EOFError
        chunks.append(b)
        got += len(b)
    return b"".join(chunks)


def _recv(fd: int) -> Any:
    (n,) = _HEADER.unpack(_read_exact(fd, _HEADER.size))
    return pickle.loads(_read_exact(fd, n))


def _shm_dir() -> str:
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()


class _Layout:
    """Where the per-frame inputs and the depth image sit in the shared file."""

    def __init__(self, n_moving: int, height: int, width: int) -> None:
        self.n_moving = n_moving
        self.shape = (height, width)
        f8 = 8
        self.xpos = 0
        self.xmat = self.xpos + n_moving * 3 * f8
        self.cam_pos = self.xmat + n_moving * 9 * f8
        self.cam_mat = self.cam_pos + 3 * f8
        self.depth = self.cam_mat + 9 * f8
        self.size = self.depth + height * width * 4

    def views(self, buf: mmap.mmap) -> tuple[np.ndarray, ...]:
        n = self.n_moving
        xpos = np.ndarray((n, 3), np.float64, buf, self.xpos)
        xmat = np.ndarray((n, 9), np.float64, buf, self.xmat)
        cpos = np.ndarray((3,), np.float64, buf, self.cam_pos)
        cmat = np.ndarray((9,), np.float64, buf, self.cam_mat)
        depth = np.ndarray(self.shape, np.float32, buf, self.depth)
        return xpos, xmat, cpos, cmat, depth


#: Signals held back while a request and its reply cross the pipes.
_HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def _signals_held():
    """Hold Ctrl-C and ``kill`` back until the block ends, then act on them as before.
    Their KeyboardInterrupt raised halfway through a message would leave the pipes out of
    step, and the next request, such as the one closing the camera for a run's report,
    would wait for ever. (Python runs signal handlers in the main thread only, so
    handlers that note the signal defer it; masking the signal would not, another thread
    would take it.)"""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[tuple[int, Any]] = []
    old = {s: signal.signal(s, lambda signum, frame: caught.append((signum, frame))) for s in _HELD_SIGNALS}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)
        if caught:
            signum, frame = caught[0]
            h = old[signum]
            if callable(h):
                h(signum, frame)
            elif h == signal.SIG_DFL:
                os.kill(os.getpid(), signum)


class RenderServer:
    """The client side of one render server process (see the module docstring)."""

    def __init__(self) -> None:
        r_req, w_req = os.pipe()
        r_rep, w_rep = os.pipe()
        root = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([root, *([env["PYTHONPATH"]] if env.get("PYTHONPATH") else [])])
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "sim.simulator.render_process", str(r_req), str(w_rep)],
            pass_fds=(r_req, w_rep),
            stdin=subprocess.DEVNULL,
            env=env,
            close_fds=True,
        )
        os.close(r_req)
        os.close(w_rep)
        self._w, self._r = w_req, r_rep
        self.pid = os.getpid()
        self._lock = threading.Lock()
        self._next = 0

    def request(self, op: str, *args: Any) -> Any:
        with self._lock, _signals_held():
            try:
                _send(self._w, (op, *args))
                ok, value = _recv(self._r)
            except (EOFError, BrokenPipeError, OSError) as exc:
                code = self.proc.poll()
                raise RuntimeError(
                    f"the depth render process (pid {self.proc.pid}) exited"
                    + (f" with code {code}" if code is not None else "")
                    + "; its error, if any, is on stderr above"
                ) from exc
        if not ok:
            raise value
        return value

    def new_id(self) -> int:
        self._next += 1
        return self._next

    def close(self) -> None:
        if self.pid != os.getpid():
            return  # a forked copy: the server belongs to the parent
        try:
            os.close(self._w)  # the server exits on end of file
            os.close(self._r)
        except OSError:
            pass
        try:
            self.proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.proc.kill()


_server: RenderServer | None = None
_server_lock = threading.Lock()


def server() -> RenderServer:
    """This process's render server, started on first use (and again after a fork)."""
    global _server
    with _server_lock:
        if _server is None or _server.pid != os.getpid() or _server.proc.poll() is not None:
            _server = RenderServer()
        return _server


@atexit.register
def _close_server() -> None:
    if _server is not None:
        _server.close()


class ProcessGLDepth:
    """:class:`sim.simulator.gl_depth.GLDepth` run by the render server; same interface,
    same frames."""

    def __init__(self, model: mujoco.MjModel, camera_id: int, intr: CameraIntrinsics, far_m: float = math.inf) -> None:
        self.model = model
        self.camera_id = camera_id
        self.intr = intr
        self.far_m = float(far_m)
        self._moving = np.flatnonzero(model.geom_bodyid != 0)
        self._layout = _Layout(len(self._moving), intr.height, intr.width)
        self._pid = -1
        self._open()

    def _open(self) -> None:
        srv = server()
        fd, path = tempfile.mkstemp(prefix="depthnav-render-", dir=_shm_dir())
        try:
            os.ftruncate(fd, self._layout.size)
            self._buf = mmap.mmap(fd, self._layout.size)
        finally:
            os.close(fd)
        try:
            self._id = srv.new_id()
            srv.request("open", self._id, self.model, self.camera_id, self.intr, self.far_m, path, self._moving)
        finally:
            os.unlink(path)  # both sides hold a mapping; the name is no longer needed
        self._xpos, self._xmat, self._cpos, self._cmat, self._depth = self._layout.views(self._buf)
        self._server, self._pid = srv, os.getpid()

    def render(self, data: mujoco.MjData, out: np.ndarray | None = None) -> np.ndarray:
        """Clean planar depth (float32, metres, 0 = background)."""
        if self._pid != os.getpid():
            self._open()  # forked: this process needs its own server
        if out is None:
            out = np.empty((self.intr.height, self.intr.width), dtype=np.float32)
        np.take(data.geom_xpos, self._moving, axis=0, out=self._xpos)
        np.take(data.geom_xmat, self._moving, axis=0, out=self._xmat)
        self._cpos[:] = data.cam_xpos[self.camera_id]
        self._cmat[:] = data.cam_xmat[self.camera_id]
        self._server.request("render", self._id)
        out[:] = self._depth
        return out

    def close(self) -> None:
        if self._pid == os.getpid() and self._pid != -1:
            try:
                self._server.request("close", self._id)
            except RuntimeError:
                pass
            self._pid = -1
        buf = getattr(self, "_buf", None)
        if buf is not None:
            self._xpos = self._xmat = self._cpos = self._cmat = self._depth = None
            try:
                buf.close()
            except BufferError:
                pass
            self._buf = None

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass


# -- the server --------------------------------------------------------------------------
class _Camera:
    def __init__(self, model, camera_id, intr, far_m, path, moving) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, self.data)  # the world body's geoms never move
        self.gl = GLDepth(model, camera_id, intr, far_m)
        self.camera_id = camera_id
        self.moving = moving
        layout = _Layout(len(moving), intr.height, intr.width)
        with open(path, "r+b") as f:
            self.buf = mmap.mmap(f.fileno(), layout.size)
        self.xpos, self.xmat, self.cpos, self.cmat, self.depth = layout.views(self.buf)

    def render(self) -> None:
        d = self.data
        d.geom_xpos[self.moving] = self.xpos
        d.geom_xmat[self.moving] = self.xmat
        d.cam_xpos[self.camera_id] = self.cpos
        d.cam_xmat[self.camera_id] = self.cmat
        self.gl.render(d, self.depth)

    def close(self) -> None:
        self.gl.close()


def _serve(r: int, w: int) -> None:
    cams: dict[int, _Camera] = {}
    while True:
        try:
            msg = _recv(r)
        except EOFError:
            break
        op, cid, *args = msg
        try:
            if op == "render":
                cams[cid].render()
                result = None
            elif op == "open":
                cams[cid] = _Camera(*args)
                result = None
            elif op == "close":
                cam = cams.pop(cid, None)
                if cam is not None:
                    cam.close()
                result = None
            else:
                raise ValueError(f"unknown request {op!r}")
        except Exception as exc:  # handed back to the caller, which raises it
            if not isinstance(exc, InputError | RuntimeError):
                exc = RuntimeError(f"{type(exc).__name__}: {exc}")
            _send(w, (False, exc))
            continue
        _send(w, (True, result))
    for cam in cams.values():
        cam.close()


if __name__ == "__main__":
    _serve(int(sys.argv[1]), int(sys.argv[2]))
