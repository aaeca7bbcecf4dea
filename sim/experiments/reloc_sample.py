"""Relocalization from unknown starts on the map alone: how often, and how fast, the
robot finds itself at random places of a region when the only thing it sees is the map.

Each trial starts the robot stack with an unknown pose (``RobotStack.reset(None)``) at a
random free place of the region, with a random heading, and closes the loop for up to
``seconds``: the stack decides (it looks round, drives to find walls, explores on its
modes), the robot moves exactly as commanded (perfect odometry), and the camera sees the
map's walls and floor from the true pose (:class:`sim.simulator.map_depth.MapDepth`,
with ``noise_m`` of Gaussian depth noise: without any, standing still reads as stale
frames). Nothing the map lacks is in view, so a failure here is the map's own ambiguity
or its lack of walls in range, not clutter: what the kidnapped scenario measures with
people and furniture, this separates. With ``furniture`` pieces, clutter comes back in a
controlled form: that many random pieces stand in the map's open areas (as the scenarios
place them, :func:`sim.simulator.building.random_furniture`), seen as the full-height
faces of their footprints, and no start lies on one. With ``odometry_noise``, the stack
dead-reckons on the simulator's odometry model instead (:class:`sim.simulator.robot.Odometry`:
that relative error on each frame's increments, at the trial's 10 frames per second):
its scan is then placed by drifting dead reckoning, as on a real robot.
``depthnav reloc-sample`` runs it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import compose_pose, relative_pose
from autonomy.maps.raycast import SceneQuery, load_or_build
from autonomy.stack import LOCALIZATION_GRID, RobotStack, StackConfig
from sim.simulator.actors import Furniture
from sim.simulator.blueprints import load_blueprint
from sim.simulator.building import Building, random_furniture
from sim.simulator.map_depth import MapDepth
from sim.simulator.robot import Odometry, OdometryConfig

RATE_HZ = 10.0
"""Frames per second of a trial (the stack's decisions do not need the camera's 30)."""
MAX_FURNITURE = 100
"""Most pieces ``--furniture`` places (each is tried at many random places until it fits,
so an impossible count would search for minutes before it failed)."""


@dataclass(frozen=True)
class Trial:
    """One unknown start: where, and how it ended."""

    start: tuple[float, float, float]
    relocalized: bool
    seconds: float
    """Time to the accepted mode (or the trial's length when none was)."""
    error_m: float
    """Distance from the accepted mode to the truth (NaN when none was)."""
    heading_error_deg: float
    reason: str
    """The last search's verdict (why it accepted, or why it had not)."""


def parse_region(text: str) -> tuple[float, float, float, float]:
    """``"x0,y0,x1,y1"`` (metres) -> the box, checked."""
    try:
        x0, y0, x1, y1 = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"--region: expected x0,y0,x1,y1 in metres, got {text!r}") from None
    if not (x1 > x0 and y1 > y0) or not all(math.isfinite(v) for v in (x0, y0, x1, y1)):
        raise InputError(f"--region: expected x0 < x1 and y0 < y1, got {text!r}")
    return x0, y0, x1, y1


def start_poses(
    building: Building, radius_m: float, region: tuple[float, float, float, float] | None, n: int, rng: np.random.Generator,
    pieces: tuple[Furniture, ...] = (),
) -> np.ndarray:
    """``n`` poses (n, 3) uniform over the building's free space for a robot of radius
    ``radius_m`` (the free space the relocalization searches), inside ``region`` (None:
    anywhere), clear of the furniture ``pieces``, with uniform headings."""
    fs = building.free_space(radius_m)
    rows, cols = fs.free_cells(radius_m, region=None, cache=False)
    xy = fs.centres(rows, cols)
    if region is not None:
        x0, y0, x1, y1 = region
        xy = xy[(xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)]
    for f in pieces:
        xy = xy[np.hypot(xy[:, 0] - f.x, xy[:, 1] - f.y) > f.half_diagonal + radius_m]
    if not len(xy):
        raise InputError(f"--region: no free place of the map inside {region}")
    pick = xy[rng.integers(0, len(xy), size=n)]
    return np.column_stack([pick, rng.uniform(-math.pi, math.pi, size=n)])


def run_trial(stack: RobotStack, scene: SceneQuery, depth: MapDepth, start: np.ndarray, seconds: float, noise_m: float,
              rng: np.random.Generator, clutter: np.ndarray | None = None, odometry: Odometry | None = None) -> Trial:
    """One unknown start at ``start`` (see the module docstring); ``clutter``: (K, 4)
    segments the camera sees besides the map; ``odometry``: the noisy odometry the stack
    dead-reckons on (None: the commanded motion, exactly)."""
    out = stack.reset(None)
    truth, inc, t = np.asarray(start, dtype=np.float64).copy(), None, 0.0
    if odometry is not None:
        odometry.reset(truth)
    while t < seconds:
        frame = depth.render(scene, truth, clutter)
        if noise_m > 0:
            frame = np.where(frame > 0, frame + rng.normal(0.0, noise_m, frame.shape), 0.0).astype(np.float32)
        out = stack.step(frame, inc, t)
        if not out.relocalizing:
            break
        move = out.velocity / RATE_HZ
        truth = compose_pose(truth, move)
        inc = move if odometry is None else odometry.update(truth)
        t += 1.0 / RATE_HZ
    found = not out.relocalizing
    err = relative_pose(truth, out.estimate) if found else np.full(3, math.nan)
    last = out.last_search
    return Trial(
        start=(round(float(start[0]), 3), round(float(start[1]), 3), round(float(start[2]), 3)),
        relocalized=found,
        seconds=round(t, 2),
        error_m=round(float(math.hypot(err[0], err[1])), 3),
        heading_error_deg=round(float(math.degrees(abs(err[2]))), 2),
        reason="" if last is None else last.reason,
    )


def sample(map_name: str, region: tuple[float, float, float, float] | None, n: int, seed: int, seconds: float = 60.0,
           noise_m: float = 0.003, progress=None, furniture: int = 0, odometry_noise: float = 0.0) -> list[Trial]:
    """``n`` trials at random places of ``region`` on a shipped or given map (stem path),
    among ``furniture`` random pieces the map lacks, dead-reckoning with ``odometry_noise``
    relative error on each frame's increments (0: exactly)."""
    if n < 1:
        raise InputError(f"--n: expected at least 1 trial, got {n}")
    if not 0 <= furniture <= MAX_FURNITURE:
        raise InputError(f"--furniture: expected 0 to {MAX_FURNITURE} pieces, got {furniture}")
    if not (math.isfinite(seconds) and seconds > 0):
        raise InputError(f"--seconds: expected a finite number above 0, got {seconds}")
    if not (math.isfinite(noise_m) and noise_m >= 0):
        raise InputError(f"--noise-m: expected a finite depth noise of 0 m or more, got {noise_m}")
    if not (math.isfinite(odometry_noise) and 0 <= odometry_noise < 1):
        raise InputError(f"--odometry-noise: expected a relative error from 0 to below 1, got {odometry_noise}")
    bp = load_blueprint(map_name)
    scene = SceneQuery(bp.vectormap, load_or_build(bp.vectormap, None, LOCALIZATION_GRID))
    cfg = StackConfig()
    radius = cfg.avoidance.robot_radius_m
    stack = RobotStack(bp.vectormap, bp.navgraph, cfg, rng=np.random.default_rng(seed), scene=scene)
    stack.prepare_recovery()
    building = Building(bp.vectormap, bp.navgraph, tuple(bp.open_areas), tuple(bp.rooms))
    pieces: tuple[Furniture, ...] = ()
    if furniture:
        # Their own stream: a seed's pieces are the same whatever --n and --region.
        try:
            pieces = random_furniture(building, furniture, np.random.default_rng([seed, 1]), radius)
        except InputError as e:
            # The scenario key the placement names is not what the user typed.
            raise InputError(f"--furniture: {str(e).removeprefix('actors.random_furniture: ')}") from None
    clutter = np.vstack([f.outline() for f in pieces]) if pieces else None
    rng = np.random.default_rng(seed)
    depth = MapDepth(cfg.camera)
    # Its own stream too: the places and headings are the same with and without it.
    odometry = None
    if odometry_noise > 0:
        odometry = Odometry(OdometryConfig(odometry_noise, odometry_noise), np.random.default_rng([seed, 2]), np.zeros(3))
    out = []
    for start in start_poses(building, radius, region, n, rng, pieces):
        out.append(run_trial(stack, scene, depth, start, seconds, noise_m, rng, clutter, odometry))
        if progress is not None:
            progress(out[-1])
    return out
