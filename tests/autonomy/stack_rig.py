"""What the robot stack's recovery tests share (``test_stack_frames``,
``test_stack_recovery``, ``test_stack_unknown_start``): the shipped corridor_loop map
without a simulator, a stack on it, synthetic depth frames, and loops that feed them.

Depth frames are synthetic: constant arrays for the frame checks, and for the rest a
closed-form render of the map's walls (vertical planes) and the floor through the
default Kinect mount, the frame the camera would see at a known pose.
"""

from __future__ import annotations

import numpy as np

from autonomy.common.geometry import compose_pose
from autonomy.maps.raycast import SceneQuery, load_or_build
from autonomy.perception.camera import DepthCamera
from autonomy.stack import LOCALIZATION_GRID, RobotStack, StackConfig
from sim.simulator.blueprints import ASSETS_DIR, load_blueprint
from sim.simulator.map_depth import MapDepth

CAM = DepthCamera()
SHAPE = (CAM.intrinsics.height, CAM.intrinsics.width)
MAP_PATH = ASSETS_DIR / "corridor_loop.vectormap.txt"
#: A corridor spot by an office door whose surroundings no other place repeats (the
#: relocalization tests use it too), facing along the corridor.
START = np.array([38.31, 33.34, -2.56])
FPS = 30.0


def corridor_loop():
    """The map's blueprint and its ray-cast query (the tests' ``building`` fixture)."""
    bp = load_blueprint("corridor_loop")
    scene = SceneQuery(bp.vectormap, load_or_build(bp.vectormap, MAP_PATH, LOCALIZATION_GRID))
    return bp, scene


def make_stack(building, pose: np.ndarray | None = START, **cfg) -> RobotStack:
    bp, scene = building
    stack = RobotStack(bp.vectormap, bp.navgraph, StackConfig(**cfg), rng=np.random.default_rng(0), fspf_seed=3, scene=scene)
    stack.reset(pose)
    return stack


_MAP_DEPTH = MapDepth(CAM)


def render(scene: SceneQuery, pose: np.ndarray) -> np.ndarray:
    """Planar depth of the map's walls and the floor seen from ``pose``
    (:class:`sim.simulator.map_depth.MapDepth`)."""
    return _MAP_DEPTH.render(scene, pose)


def wall(depth_m: float = 2.0) -> np.ndarray:
    return np.full(SHAPE, depth_m, np.float32)


def count_updates(stack: RobotStack, monkeypatch) -> list[int]:
    """Count CGR's observation updates (a frame that is not used must not reach CGR)."""
    calls = [0]
    original = stack.localizer.update

    def update(*args, **kwargs):
        calls[0] += 1
        return original(*args, **kwargs)

    monkeypatch.setattr(stack.localizer, "update", update)
    return calls


def drive(stack: RobotStack, frames, t0: float = 0.0, fps: float = FPS, increment=None):
    """Feed ``frames`` (depth or None) at ``fps`` from ``t0``; returns (t, decide()) per frame."""
    out = []
    for k, depth in enumerate(frames):
        t = t0 + (k + 1) / fps
        stack.perceive(depth)
        stack.localize(np.zeros(3) if increment is None else increment, t)
        out.append((t, stack.decide(t)))
    return out


def follow(stack: RobotStack, scene: SceneQuery, truth: np.ndarray, t: float, until_s: float, fps: float = 10.0):
    """The robot does what decide() says (perfect odometry) and the camera sees the map
    from the true pose, until it has relocalized or ``until_s``; returns the truth, the
    time and the commands' (t, state, velocity)."""
    commands = []
    while t < until_s and not any(e["event"] == "relocalized" for e in stack.state.events):
        cmd = stack.decide(t)
        commands.append((t, cmd.state, cmd.velocity.copy()))
        inc = cmd.velocity / fps
        truth = compose_pose(truth, inc)
        t += 1.0 / fps
        stack.perceive(render(scene, truth))
        stack.localize(inc, t)
    return truth, t, commands


def settle(stack: RobotStack, scene: SceneQuery, seconds: float, fps: float = 10.0) -> float:
    """Standing at the belief's pose (the frame repeats: standing still, not stale)."""
    depth = render(scene, stack.state.pose.copy())
    for k in range(int(seconds * fps)):
        stack.perceive(depth)
        stack.localize(np.zeros(3), (k + 1) / fps)
    return seconds
