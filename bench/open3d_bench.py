"""Our plane finders beside Open3D's on the same frames (``bench_open3d``, a group of
bench/run.py, run only when ``open3d`` is installed: ``pip install open3d``).

On the same 640 x 480 noisy Kinect frames of the corridor loop (bench/planes_bench.py):

- ``o3d_plane_frame``: Open3D's ``PointCloud.segment_plane`` on a whole frame's
  point cloud, with FSPF's plane-fit tolerance (BV2012 Table I: epsilon = 2 cm), 3 points per
  hypothesis and 1,000 iterations; ``fspf_speedup`` is its median over FSPF's on the frame.
  The two do different work (FSPF filters every planar neighbourhood of the frame from a
  fixed budget of samples; segment_plane finds the one biggest plane and scores every
  hypothesis on all points); the ratio says what a user would wait for either.
- ``o3d_plane_ransac``: ``segment_plane`` with our multi-plane RANSAC's first-plane
  settings (1 cm threshold, 500 iterations) on the same clouds; ``ransac_speedup`` is its
  median over our RANSAC stopped at the first plane (which scores hypotheses on a
  2,048-point sample and refits on all inliers).

Open3D runs with its default threads (both cores); ours on one. Run alone:
``.venv/bin/python bench/open3d_bench.py [--quick]``.
"""

from __future__ import annotations

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


def bench_open3d(results: dict[str, Result], quick: bool) -> None:
    try:
        import open3d as o3d
    except ImportError as e:  # not installed, or a system library it needs is missing
        print(f"  the Open3D comparison is skipped: {e} (pip install open3d; on Debian it also needs libusb-1.0-0)", file=sys.stderr)
        return
    from planes_bench import corridor_frames

    from autonomy.perception.fspf import FSPFConfig, fspf
    from autonomy.planes import RansacConfig, depth_to_cloud, ransac_planes

    depths, poses, intr = corridor_frames(8)
    clouds = [depth_to_cloud(d, intr, t[:3, :3])[0] for d, t in zip(depths, poses, strict=True)]
    pcds = []
    for c in clouds:
        p = o3d.geometry.PointCloud()
        p.points = o3d.utility.Vector3dVector(np.asarray(c, dtype=np.float64))
        pcds.append(p)
    n = 10 if quick else 40
    it = iter(range(10**7))
    fcfg = FSPFConfig()
    rc1 = RansacConfig(max_planes=1)

    def ours_fspf() -> None:
        k = next(it)
        fspf(depths[k % len(depths)], intr, fcfg, seed=k)

    def o3d_fspf_like() -> None:
        k = next(it)
        pcds[k % len(pcds)].segment_plane(distance_threshold=fcfg.epsilon_m, ransac_n=3, num_iterations=1000)

    def ours_ransac() -> None:
        k = next(it)
        ransac_planes(clouds[k % len(clouds)], rc1, k)

    def o3d_ransac_like() -> None:
        k = next(it)
        pcds[k % len(pcds)].segment_plane(distance_threshold=rc1.distance_threshold_m, ransac_n=3, num_iterations=rc1.max_iterations)

    f = entry(timeit(ours_fspf, n, warmup=2))
    o = entry(timeit(o3d_fspf_like, n, warmup=2))
    o["fspf_ms"] = f["median_ms"]
    o["fspf_speedup"] = round(o["median_ms"] / f["median_ms"], 1)
    results["o3d_plane_frame"] = o
    r = entry(timeit(ours_ransac, n, warmup=2))
    o = entry(timeit(o3d_ransac_like, n, warmup=2))
    o["ransac_ms"] = r["median_ms"]
    o["ransac_speedup"] = round(o["median_ms"] / r["median_ms"], 1)
    results["o3d_plane_ransac"] = o
    print(f"  open3d {o3d.__version__}: FSPF {results['o3d_plane_frame']['fspf_speedup']}x faster than segment_plane "
          f"on a frame; our RANSAC {o['ransac_speedup']}x faster on the first plane", file=sys.stderr)


if __name__ == "__main__":
    from run import print_table

    res: dict[str, Result] = {}
    bench_open3d(res, "--quick" in sys.argv)
    print_table(res)
