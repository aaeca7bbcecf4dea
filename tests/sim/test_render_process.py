"""The render server process: the same frames as rendering here, and safe with PyTorch.

Rendering with Mesa in the caller's process makes LLVM's symbols global there, and a
later ``import triton`` (PyTorch's compiler, loaded by ``torch._dynamo`` at the first
optimizer step) binds to them and crashes. The checks that load Mesa into a process
run in child processes, so this test process stays clean.
"""

from __future__ import annotations

import importlib.util
import multiprocessing
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from autonomy.maps.vectormap import VectorMap
from autonomy.perception.camera import CameraIntrinsics
from sim.simulator.kinect import make_depth_backend
from sim.simulator.world import WorldConfig, build_world
from tests.helpers import GL

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
HAS_TRITON = importlib.util.find_spec("triton") is not None
HAS_SB3 = importlib.util.find_spec("stable_baselines3") is not None
NO_TRITON = "triton (the `rl` extra: pip install -e '.[rl]') is not installed"


def _python(code: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT), MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout
    )


def _room():
    vm = VectorMap.from_segments(np.array([[0, 0, 8, 0], [8, 0, 8, 5], [8, 5, 0, 5], [0, 5, 0, 0], [4, 1, 5, 2.5]], dtype=np.float64))
    return build_world(vm, world=WorldConfig(), intrinsics=CameraIntrinsics().scaled(160, 120), start_pose=(1.0, 2.5, 0.2))


def test_frames_from_the_render_process_are_the_in_process_frames_bit_for_bit() -> None:
    """An env with people and furniture, stepped: the server's frame and an in-process
    GLDepth's frame of the same data are identical."""
    r = _python(
        """
        import numpy as np, gymnasium as gym, sim
        from sim.simulator.gl_depth import GLDepth
        from sim.simulator.render_process import ProcessGLDepth
        env = gym.make("DepthNav-v0", n_people=3, n_furniture=3)
        env.reset(seed=3)
        site = env.unwrapped.site
        b = site.camera.backend
        assert isinstance(b, ProcessGLDepth), type(b)
        g = GLDepth(site.world.model, site.world.camera_id, b.intr, b.far_m)
        rng = np.random.default_rng(0)
        same = 0
        for k in range(30):
            env.step(rng.uniform(-1, 1, 3))
            a, c = b.render(site.world.data).copy(), g.render(site.world.data)
            same += int(np.array_equal(a, c) and (a > 0).mean() > 0.3)
        print("SAME", same)
        """
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "SAME 30" in r.stdout


@pytest.mark.skipif(not HAS_TRITON, reason=NO_TRITON)
def test_triton_after_rendering_crashes_in_process_and_not_with_the_render_process() -> None:
    """The old path (GL in this process) dies with SIGSEGV in triton's static
    initialisers; the default (the render server) imports triton and keeps rendering."""
    code = """
        import gymnasium as gym, numpy as np, sim
        from sim.simulator.kinect import KinectConfig
        env = gym.make("DepthNav-v0", kinect=KinectConfig(render_process={flag}))
        env.reset(seed=0)
        import triton
        obs, *_ = env.step(np.zeros(3))
        print("rendered after triton", float(obs["depth"].max()) > 0)
    """
    old = _python(code.format(flag=False))
    assert old.returncode == -signal.SIGSEGV, (old.returncode, old.stderr[-2000:])
    new = _python(code.format(flag=True))
    assert new.returncode == 0, new.stderr[-2000:]
    assert "rendered after triton True" in new.stdout


@pytest.mark.slow
@pytest.mark.skipif(not (HAS_TRITON and HAS_SB3), reason=NO_TRITON)
def test_the_stable_baselines3_snippet_trains_to_the_end() -> None:
    """PPO on DepthNav-v0, with torch imported after the env has rendered (as SB3 does):
    the first optimizer step loads torch._dynamo and triton."""
    r = _python(
        """
        import gymnasium as gym, sim
        from stable_baselines3 import PPO
        from stable_baselines3.common.env_util import make_vec_env
        env = make_vec_env("DepthNav-v0", n_envs=1, env_kwargs=dict(depth_shape=(60, 80), observe_scan=40))
        model = PPO("MultiInputPolicy", env, n_steps=512).learn(2048)
        import sys
        print("timesteps", model.num_timesteps, "dynamo loaded", "torch._dynamo" in sys.modules)
        """,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert "timesteps 2048 dynamo loaded True" in r.stdout


@pytest.mark.skipif(not HAS_TRITON, reason=NO_TRITON)
def test_a_scenario_run_then_triton_in_the_same_process() -> None:
    r = _python(
        """
        import tempfile
        from sim.experiments.runner import run_scenario
        from sim.scenario import SCENARIOS_DIR, load_scenario
        scn = load_scenario(SCENARIOS_DIR / "demo.toml", ["mission.max_duration_s=1.0"])
        rep = run_scenario(scn, tempfile.mkdtemp(), seed=1, progress=False)
        import triton
        print("frames", rep["metrics"]["frames"] > 0)
        """
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "frames True" in r.stdout


def _render_in_child(q) -> None:
    w = _room()
    q.put(make_depth_backend(w.model, w.camera_id, CameraIntrinsics().scaled(160, 120), "gl").render(w.data).copy())


def test_a_forked_child_renders_with_its_own_server() -> None:
    """A process forked after the parent rendered (gymnasium's default AsyncVectorEnv
    context) starts its own server and gets the same frame."""
    w = _room()
    backend = make_depth_backend(w.model, w.camera_id, CameraIntrinsics().scaled(160, 120), "gl")
    mine = backend.render(w.data).copy()
    ctx = multiprocessing.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_render_in_child, args=(q,))
    p.start()
    theirs = q.get(timeout=120)
    p.join(timeout=60)
    assert p.exitcode == 0
    assert np.array_equal(mine, theirs) and (mine > 0).mean() > 0.3
    assert np.array_equal(backend.render(w.data), mine)  # the parent's server still serves


def test_a_dead_server_is_a_clear_error_and_the_next_camera_gets_a_new_one() -> None:
    from sim.simulator import render_process

    w = _room()
    intr = CameraIntrinsics().scaled(160, 120)
    backend = make_depth_backend(w.model, w.camera_id, intr, "gl")
    first = backend.render(w.data).copy()
    srv = render_process.server()
    srv.proc.kill()
    srv.proc.wait()
    with pytest.raises(RuntimeError, match="depth render process .* exited"):
        backend.render(w.data)
    again = make_depth_backend(w.model, w.camera_id, intr, "gl")
    assert render_process.server() is not srv
    assert np.array_equal(again.render(w.data), first)


def test_this_test_process_never_loaded_mesa() -> None:
    _room_backend = make_depth_backend(_room().model, 0, CameraIntrinsics().scaled(160, 120), "gl")
    with open(f"/proc/{os.getpid()}/maps") as f:
        maps = f.read()
    assert "libLLVM" not in maps and "swrast_dri" not in maps and "libgallium" not in maps
    _room_backend.close()


def test_ctrl_c_during_a_request_waits_for_its_reply() -> None:
    """SIGINT delivered between a request and its reply raises KeyboardInterrupt only
    after the reply is read: the pipes stay in step and the next request (a run's
    report closes the camera) is answered instead of waiting for ever."""
    r = _python(
        """
        import os, signal, numpy as np
        signal.signal(signal.SIGINT, signal.default_int_handler)  # a test runner's worker may ignore it
        from autonomy.perception.camera import CameraIntrinsics
        from autonomy.maps.vectormap import VectorMap
        from sim.simulator import render_process as rp
        from sim.simulator.world import WorldConfig, build_world
        vm = VectorMap.from_segments(np.array([[0, 0, 8, 0], [8, 0, 8, 5], [8, 5, 0, 5], [0, 5, 0, 0]], dtype=np.float64))
        w = build_world(vm, world=WorldConfig(), intrinsics=CameraIntrinsics().scaled(160, 120), start_pose=(1.0, 2.5, 0.2))
        cam = rp.ProcessGLDepth(w.model, w.camera_id, CameraIntrinsics().scaled(160, 120))
        first = cam.render(w.data).copy()
        real = rp._recv
        def recv_after_ctrl_c(fd):
            os.kill(os.getpid(), signal.SIGINT)  # arrives while the reply is on its way
            return real(fd)
        rp._recv = recv_after_ctrl_c
        try:
            cam.render(w.data)
            print("NOT INTERRUPTED")
        except KeyboardInterrupt:
            print("INTERRUPTED AFTER THE REPLY")
        rp._recv = real
        again = cam.render(w.data)
        print("SAME", bool(np.array_equal(first, again) and (first > 0).mean() > 0.3))
        # In step: no reply is left waiting in the pipe after a request is answered.
        import select
        print("PENDING", bool(select.select([rp.server()._r], [], [], 0.5)[0]))
        cam.close()
        """,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "INTERRUPTED AFTER THE REPLY" in r.stdout and "SAME True" in r.stdout and "PENDING False" in r.stdout, r.stdout
