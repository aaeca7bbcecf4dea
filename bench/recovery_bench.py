"""Recovery benchmarks: the health check of one frame, the view check and the missing-wall
count of one frame, and one global relocalization search (autonomy.localization.health,
autonomy.localization.view_check, autonomy.localization.missing_walls, autonomy.localization.relocalization)."""

from __future__ import annotations

import math
import sys

import numpy as np
from common import Result, entry, timeit

from autonomy.common.geometry import compose_pose
from autonomy.localization.health import HealthConfig, explain_points
from autonomy.localization.missing_walls import MissingWallsConfig, missing_walls
from autonomy.localization.relocalization import GlobalLocalizer, Scan
from autonomy.localization.view_check import ViewCheck, ViewCheckConfig
from autonomy.maps.freespace import FreeSpaceConfig, build_free_space
from autonomy.maps.raycast import SceneQuery, VisibilityGrid, rays_hit
from autonomy.perception.camera import DepthCamera
from autonomy.stack import LOCALIZATION_GRID
from sim.simulator import blueprints
from sim.simulator.blueprints import ASSETS_DIR
from sim.simulator.map_depth import MapDepth


def _panorama(query: SceneQuery, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A turn in place's scan at ``pose`` (robot frame): walls 0.8-4 m away, 1 cm noise,
    thinned to one point per 5 cm as the stack's scan keeps them."""
    lines = query.scene_lines(float(pose[0]), float(pose[1]))[0]
    ang = np.linspace(-math.pi, math.pi, 2880, endpoint=False)
    dirs = np.column_stack([np.cos(ang + pose[2]), np.sin(ang + pose[2])])
    idx, t = rays_hit(lines, float(pose[0]), float(pose[1]), dirs)
    ok = (idx >= 0) & (t > 0.8) & (t < 4.0)
    pts = np.column_stack([t[ok] * np.cos(ang[ok]), t[ok] * np.sin(ang[ok])]) + rng.normal(0.0, 0.01, (int(ok.sum()), 2))
    scan = Scan(0.05, 6000)
    scan.add(np.zeros(3), pts, 0.0)
    return scan.in_robot_frame(np.zeros(3))


def _floor_seen(query: SceneQuery, pose: np.ndarray) -> np.ndarray:
    """The floor points a turn in place keeps at ``pose`` (robot frame): along 500
    directions, as far as the camera's 4 m or 10 cm short of the first wall."""
    lines = query.scene_lines(float(pose[0]), float(pose[1]))[0]
    ang = np.linspace(-math.pi, math.pi, 500, endpoint=False)
    dirs = np.column_stack([np.cos(ang + pose[2]), np.sin(ang + pose[2])])
    idx, t = rays_hit(lines, float(pose[0]), float(pose[1]), dirs)
    r = np.where(idx >= 0, np.minimum(t - 0.1, 4.0), 4.0)
    return np.column_stack([r * np.cos(ang), r * np.sin(ang)])


def bench_recovery(results: dict[str, Result], quick: bool) -> None:
    rng = np.random.default_rng(0)
    bp = blueprints.load_blueprint(ASSETS_DIR / "corridor_loop")
    vm = bp.vectormap
    query = SceneQuery(vm, VisibilityGrid.build(vm, LOCALIZATION_GRID))
    fs = build_free_space(vm, FreeSpaceConfig(robot_radius_m=0.25))
    gl = GlobalLocalizer(fs, 0.25, segments=vm.segments)
    pose = np.array([*fs.sample(rng, 1, 0.5, region=0)[0], 0.4])
    scan = _panorama(query, pose, rng)
    print(f"  relocalization: {len(gl.candidates) * len(gl.headings):,} coarse hypotheses, a {len(scan)}-point scan", file=sys.stderr)
    frame = scan[np.abs(np.arctan2(scan[:, 1], scan[:, 0])) < math.radians(29.0)]
    lines = np.ascontiguousarray(query.scene_lines(float(pose[0]), float(pose[1]))[0])
    hc = HealthConfig()
    results["health_frame"] = entry(
        timeit(lambda: explain_points(lines, pose, frame, hc.explain_m, hc.through_m), 200 if quick else 2000, warmup=3), target=0.2
    )
    # The view check of one frame against the last (both ways), the robot driving 2.5 cm
    # and turning 1 degree between two closed-form renders of the map.
    cam = DepthCamera()
    step = np.array([0.025, 0.0, math.radians(1.0)])
    render = MapDepth(cam)
    depths = [render.render(query, pose), render.render(query, compose_pose(pose, step))]
    check = ViewCheck(ViewCheckConfig(), cam.intrinsics, cam.mount.robot_from_camera(), cam.min_range_m, cam.max_range_m)
    clock = [0.0, np.zeros(3)]

    def view_frame() -> None:
        clock[0] += 1.0 / 30.0
        k = int(round(clock[0] * 30.0)) % 2
        clock[1] = compose_pose(clock[1], step if k else -step)
        check.update(clock[0], clock[1], depths[k])

    results["view_check_frame"] = entry(timeit(view_frame, 200 if quick else 2000, warmup=3), target=0.5)
    # The missing-wall count of one frame at the pose it was rendered from (every pixel
    # expecting a wall is looked up).
    rc, mw = cam.mount.robot_from_camera(), MissingWallsConfig()
    results["missing_walls_frame"] = entry(
        timeit(
            lambda: missing_walls(depths[0], lines, pose, cam.intrinsics, rc, cam.min_range_m, cam.max_range_m, mw),
            200 if quick else 2000, warmup=3,
        ),
        target=0.5,
    )
    # As the stack searches: each point's viewpoint (the robot turned in place) for the
    # sight-through-walls score, when it was seen (a 40 s look: four of the pieces the
    # modes are scored in), and the floor seen all round.
    seen_from = np.zeros_like(scan)
    seen_at = np.linspace(0.0, 39.9, len(scan))
    fl = _floor_seen(query, pose)
    floor = (fl, np.zeros_like(fl))
    results["relocalize_search"] = entry(
        timeit(
            lambda: gl.search(scan, frame, lambda x, y: query.scene_lines(x, y)[0], origins=seen_from, times=seen_at, floor=floor),
            2 if quick else 5, warmup=1,
        ),
        target=1000.0,
    )
    modes = np.array([m.pose for m in gl.search(scan, origins=seen_from, times=seen_at, floor=floor).modes])
    results["relocalize_rescore"] = entry(
        timeit(lambda: gl.rescore(modes, scan, origins=seen_from, times=seen_at, floor=floor), 3 if quick else 10, warmup=1),
        target=250.0,
    )
