"""Plane-mapping benchmarks (PlaneMap): RANSAC and randomized Hough on real Kinect frames.

``bench_planes(results, quick)`` adds, in bench/run.py's format
(``{name: {median_ms, min_ms, max_ms, target_ms, paper_ms}}``):

- ``planes_cloud``: a 640 x 480 depth frame to its point cloud (sensor-centred, z up);
- ``ransac_first_plane``: multi-plane RANSAC stopped after the first plane (target 5 ms;
  the paper: 50 ms on a 2.8 GHz Core 2 Duo);
- ``ransac_all_planes``: RANSAC, all planes (up to 8; target 20 ms);
- ``hough_plane``: randomized Hough, time per detected plane (a frame's time divided by
  its planes; target 20 ms; the paper: 170 ms), with extra keys ``accumulator_mb``
  (our sparse accumulator, target <= 16 MB), ``dense_accumulator_mb`` (the paper's
  grid as a dense int32 array) and ``planes_per_frame``;
- ``hough_dense_reset``: resetting that dense accumulator once (the paper's bottleneck).

Frames: noisy Kinect frames rendered along the corridor loop of Experiment III (camera
looking right, level) at corners, doorways and straight walls. Run alone with
``python bench/planes_bench.py [--quick]``.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import Result, entry, timeit  # noqa: E402


def corridor_frames(n: int = 8, seed: int = 0) -> tuple[list[np.ndarray], list[np.ndarray], object]:
    """``n`` noisy 640 x 480 Kinect frames along the corridor loop: (depths, world_from_camera, intrinsics)."""
    import math

    from autonomy.planes import pose_transform
    from sim.experiments.mapping.loop_driver import LoopDriver
    from sim.scenes.corridor import (
        CorridorScene,
        build_corridor_world,
        corridor_path,
        robot_from_camera,
    )
    from sim.simulator.kinect import KinectCamera, KinectConfig

    scene = CorridorScene()
    world = build_corridor_world(scene)
    cfg = KinectConfig()
    cam = KinectCamera(world.model, world.camera_id, cfg)
    drv = LoopDriver(corridor_path(scene), 1.0, 0.5)
    depths, poses = [], []
    try:
        for k in range(n):
            # Spread over the lap; every other frame turned 30 degrees into the next corner.
            s = (k + 0.5) / n * drv.lap_m
            xy, heading = drv.point(s)
            yaw = heading + (math.radians(30) if k % 2 else 0.0)
            world.robot.set_pose(world.data, (float(xy[0]), float(xy[1]), yaw))
            import mujoco

            mujoco.mj_forward(world.model, world.data)
            depths.append(cam.capture(world.data, seed + k).copy())
            poses.append(pose_transform(float(xy[0]), float(xy[1]), yaw) @ robot_from_camera(scene))
    finally:
        cam.close()
    return depths, poses, cfg.intrinsics


def bench_planes(results: dict[str, Result], quick: bool) -> None:
    """Add the plane-mapping entries to ``results`` (see the module docstring)."""
    from autonomy.planes import depth_to_cloud

    depths, poses, intr = corridor_frames(8)
    clouds = [depth_to_cloud(d, intr, t[:3, :3])[0] for d, t in zip(depths, poses, strict=True)]
    print(f"  corridor frames: {len(clouds)}, {int(np.mean([len(c) for c in clouds]))} valid points on average", file=sys.stderr)
    n = 20 if quick else 100
    it = iter(range(10**7))  # one count for every timed call: the frame index and the seed

    def cloud() -> None:
        k = next(it)
        depth_to_cloud(depths[k % len(depths)], intr, poses[k % len(poses)][:3, :3])

    results["planes_cloud"] = entry(timeit(cloud, n, warmup=2))
    _bench_ransac(results, clouds, n, it)
    results["hough_plane"] = _bench_hough(clouds, n, it)
    results["hough_dense_reset"] = _bench_dense_reset(5 if quick else 20)


def _bench_ransac(results: dict[str, Result], clouds: list[np.ndarray], n: int, it) -> None:
    """RANSAC stopped after the first plane, and for all planes."""
    from autonomy.planes import RansacConfig, ransac_planes

    rc, rc1 = RansacConfig(), RansacConfig(max_planes=1)

    def ransac_first() -> None:
        k = next(it)
        ransac_planes(clouds[k % len(clouds)], rc1, k)

    results["ransac_first_plane"] = entry(timeit(ransac_first, n, warmup=2), target=5.0, paper=50.0)

    def ransac_all() -> None:
        k = next(it)
        ransac_planes(clouds[k % len(clouds)], rc, k)

    results["ransac_all_planes"] = entry(timeit(ransac_all, n, warmup=2), target=20.0)


def _dense_hough_config():
    """The paper's Hough grid (not equal-area), as a dense accumulator would hold it."""
    from autonomy.planes import HoughConfig

    return dataclasses.replace(HoughConfig(), equal_area=False)


def _bench_hough(clouds: list[np.ndarray], n: int, it) -> Result:
    """Randomized Hough's time per detected plane, with the accumulators' sizes."""
    from autonomy.planes import (
        HoughConfig,
        SparseAccumulator,
        accumulator_nbytes,
        dense_accumulator_nbytes,
        hough_planes,
    )

    hc = HoughConfig()
    acc = SparseAccumulator(hc)
    per_plane: list[float] = []
    planes: list[int] = []
    hough_planes(clouds[0], hc, 0, acc)  # warm-up (JIT)
    for _ in range(n):
        k = next(it)
        det = hough_planes(clouds[k % len(clouds)], hc, k, acc)
        if det.planes:
            per_plane.append(det.total_ms / len(det.planes))
        planes.append(len(det.planes))
    e = entry(per_plane or [float("nan")], target=20.0, paper=170.0)
    e["accumulator_mb"] = round(accumulator_nbytes(hc) / 1e6, 3)
    e["accumulator_target_mb"] = 16.0
    e["dense_accumulator_mb"] = round(dense_accumulator_nbytes(_dense_hough_config()) / 1e6, 1)
    e["planes_per_frame"] = round(float(np.mean(planes)), 2)
    return e


def _bench_dense_reset(repeat: int) -> Result:
    """Zeroing the paper's dense accumulator once (its bottleneck)."""
    from autonomy.planes import dense_accumulator_nbytes

    dense = np.zeros(dense_accumulator_nbytes(_dense_hough_config()) // 4, dtype=np.int32)
    return entry(timeit(lambda: dense.fill(0), repeat, warmup=1))


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    results: dict[str, Result] = {}
    bench_planes(results, args.quick)
    for name, r in results.items():
        extra = {k: v for k, v in r.items() if k not in ("median_ms", "min_ms", "max_ms", "target_ms", "paper_ms")}
        print(
            f"{name:<22}{r['median_ms']:>10.3f}{r['min_ms']:>10.3f}{r['max_ms']:>10.3f}"
            f"{'-' if r['target_ms'] is None else r['target_ms']:>8}{'-' if r['paper_ms'] is None else r['paper_ms']:>8}  {extra or ''}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
