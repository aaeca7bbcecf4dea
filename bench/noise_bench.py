"""The Kinect noise model alone on a synthetic frame, by thread count.

:func:`benchmark_noise` is the median time of ``apply_kinect_noise`` on a 640 x 480 frame
of a floor, a slanted wall and a box (no rendering, no world), after the JIT warm-up.
bench/run.py's ``kinect_noise`` row times the model on a rendered frame instead.

Run alone: ``.venv/bin/python bench/noise_bench.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from autonomy.perception.camera import CameraIntrinsics  # noqa: E402
from sim.simulator.kinect_noise import KinectNoiseConfig, apply_kinect_noise  # noqa: E402


def bench_scene(intr: CameraIntrinsics) -> np.ndarray:
    """A floor, a slanted wall and a box: a typical indoor frame (float32 planar depth)."""
    xn = ((np.arange(intr.width, dtype=np.float64) - intr.cx) / intr.fx).astype(np.float32)
    yn = ((np.arange(intr.height, dtype=np.float64) - intr.cy) / intr.fy).astype(np.float32)
    x, y = np.meshgrid(xn, yn)
    wall = 3.0 / (1.0 + 0.6 * x)
    with np.errstate(divide="ignore"):
        floor = np.where(y > 0.01, 0.7 / np.maximum(y, 1e-9), np.inf)
    z = np.minimum(wall, floor)
    box = (np.abs(x - 0.1) < 0.15) & (np.abs(y - 0.05) < 0.2)
    z[box] = 1.5
    z[z > 6.0] = 0.0
    return z.astype(np.float32)


def benchmark_noise(repeats: int = 100, cfg: KinectNoiseConfig | None = None, threads: int | None = None) -> float:
    """Median milliseconds of ``apply_kinect_noise`` on the 640 x 480 :func:`bench_scene`
    (JIT warmed up); ``threads`` overrides ``cfg.threads``."""
    intr = CameraIntrinsics()
    c = cfg or KinectNoiseConfig()
    if threads is not None:
        c = replace(c, threads=threads)
    depth = bench_scene(intr)
    out = np.empty_like(depth)
    for i in range(3):
        apply_kinect_noise(depth, intr, c, i, out=out)
    times = []
    for i in range(repeats):
        t0 = time.perf_counter()
        apply_kinect_noise(depth, intr, c, i, out=out)
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e3)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=300, help="timed calls per thread count")
    args = ap.parse_args(argv)
    for n in (1, 2):
        print(f"kinect noise, 640x480, {n} thread(s): {benchmark_noise(args.repeats, threads=n):.3f} ms median")
    return 0


if __name__ == "__main__":
    sys.exit(main())
