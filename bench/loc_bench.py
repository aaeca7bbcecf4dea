"""Benchmarks of the localization comparison (BV2012, VI-A): scan simulation and replay frames.

``bench_scans(results, quick)`` times, on real noisy Kinect frames of the corridor
building, the simulated laser scans per frame (KR: one row, KS: 2,000 samples, KC: the
whole cloud, each with its down-projection to 2D points) and one replay frame per
approach (observation + CGR predict/update/estimate). Paper figures: the CPU loads of
VI-A times the 33.3 ms frame period (KR 0.01%, KS 3.6%, KC 56.6%, FSPF 16.3%).
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import entry as _entry  # noqa: E402
from common import timeit as _timeit_base  # noqa: E402


def _timeit(fn, repeat: int) -> list[float]:
    return _timeit_base(fn, repeat, warmup=2)


FRAME_MS = 1000.0 / 30.0
#: Paper: CPU load x frame period.
PAPER_MS = {"kr": 0.0001 * FRAME_MS, "ks": 0.036 * FRAME_MS, "kc": 0.566 * FRAME_MS, "fspf": 0.163 * FRAME_MS}


def _frames(n: int) -> tuple[list[np.ndarray], list[np.ndarray], object, object]:
    """``n`` noisy uint16-millimetre frames along a corridor of the shipped building, with poses."""
    from sim.simulator import blueprints
    from sim.simulator.kinect import KinectCamera, KinectConfig
    from sim.simulator.world import build_world

    bp = blueprints.load_blueprint(blueprints.ASSETS_DIR / "corridor_loop")
    cfg = KinectConfig()
    world = build_world(bp.vectormap, intrinsics=cfg.intrinsics, mount=cfg.mount, start_pose=(10.0, 6.3, 0.0))
    cam = KinectCamera(world.model, world.camera_id, cfg)
    frames, poses = [], []
    for i in range(n):
        pose = (10.0 + 0.3 * i, 6.3, 0.05 * math.sin(i))
        world.robot.set_pose(world.data, pose)
        import mujoco

        mujoco.mj_forward(world.model, world.data)
        d = cam.capture(world.data, seed=i)
        frames.append(np.clip(np.rint(d * 1000.0), 0, 65535).astype(np.uint16))
        poses.append(np.array(pose))
    cam.close()
    return frames, poses, bp, cfg


def bench_scans(results: dict, quick: bool) -> None:
    frames, poses, bp, kcfg = _frames(4 if quick else 12)
    rep = 20 if quick else 200
    _bench_scan_kinds(results, frames, kcfg, rep)
    _bench_replay_frames(results, frames, poses, bp, kcfg, rep)


def _bench_scan_kinds(results: dict, frames: list[np.ndarray], kcfg, rep: int) -> None:
    """KR, KS and KC scans of a frame, each with its down-projection to 2D points."""
    from autonomy.localization.scans import (
        ScanConfig,
        complete_scan,
        raster_scan,
        sampling_scan,
        scan_points,
    )

    intr, mount, scfg = kcfg.intrinsics, kcfg.mount, ScanConfig()
    it = iter(range(10**9))

    def frame() -> np.ndarray:
        return frames[next(it) % len(frames)]

    results["scan_kr"] = _entry(_timeit(lambda: scan_points(raster_scan(frame(), intr, mount, scfg), mount, scfg), rep), 0.5, PAPER_MS["kr"])
    results["scan_ks"] = _entry(
        _timeit(lambda: scan_points(sampling_scan(frame(), intr, mount, scfg, seed=next(it)), mount, scfg), rep), 1.0, PAPER_MS["ks"]
    )
    results["scan_kc"] = _entry(
        _timeit(lambda: scan_points(complete_scan(frame(), intr, mount, scfg), mount, scfg), max(5, rep // 4)), 20.0, PAPER_MS["kc"]
    )


def _bench_replay_frames(results: dict, frames: list[np.ndarray], poses: list[np.ndarray], bp, kcfg, rep: int) -> None:
    """One replay frame per approach: its points, then CGR predict, update and estimate."""
    from autonomy.localization.cgr import CGRLocalizer
    from autonomy.localization.scans import ScanConfig, complete_scan, raster_scan
    from autonomy.maps.raycast import SceneQuery, load_or_build
    from autonomy.stack import LOCALIZATION_GRID
    from sim.simulator.blueprints import ASSETS_DIR

    intr, mount, scfg = kcfg.intrinsics, kcfg.mount, ScanConfig()
    vm = bp.vectormap
    query = SceneQuery(vm, load_or_build(vm, ASSETS_DIR / "corridor_loop.vectormap.txt", LOCALIZATION_GRID))
    cached = {a: [fn(f, intr, mount, scfg) for f in frames] for a, fn in (("kr", raster_scan), ("kc", complete_scan))}
    for approach in ("fspf", "kr", "ks", "kc"):
        loc = CGRLocalizer(lambda x, y: query.scene_lines(x, y)[0], rng=np.random.default_rng(0))
        loc.reset(poses[0])
        one = _ReplayFrame(approach, loc, frames, poses, cached, kcfg)
        # Budget: 400 replays of a 60-120 s log in 15 min on 2 cores: ~1.5-2.5 ms a frame.
        results[f"replay_frame_{approach}"] = _entry(_timeit(one, rep), 2.5, None)


class _ReplayFrame:
    """Each call replays the next frame (the log restarts after its last) with one approach."""

    def __init__(self, approach: str, loc, frames: list[np.ndarray], poses: list[np.ndarray], cached: dict, kcfg) -> None:
        from autonomy.localization.scans import ScanConfig
        from autonomy.perception.fspf import FSPFConfig

        self.approach, self.loc, self.frames, self.poses, self.cached = approach, loc, frames, poses, cached
        self.intr, self.mount = kcfg.intrinsics, kcfg.mount
        self.scfg, self.fcfg = ScanConfig(), FSPFConfig()
        self.depth_m = np.empty((self.intr.height, self.intr.width), np.float32)
        self.k = 0

    def points(self, i: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Frame ``i``'s 2D points (and normals, from FSPF) for the localizer."""
        from autonomy.localization.scans import drop_floor, sampling_scan, scan_points
        from autonomy.perception.fspf import fspf, project_to_floor

        f, intr, mount, scfg = self.frames[i], self.intr, self.mount, self.scfg
        if self.approach == "fspf":
            np.multiply(f, np.float32(0.001), out=self.depth_m, casting="unsafe")
            res = fspf(self.depth_m, intr, self.fcfg, seed=self.k, mount=mount)
            return project_to_floor(*drop_floor(res.points, res.normals, scfg), self.fcfg.max_vertical_normal_angle_rad)
        if self.approach == "ks":
            return scan_points(sampling_scan(f, intr, mount, scfg, seed=self.k), mount, scfg), None
        return scan_points(self.cached[self.approach][i], mount, scfg), None

    def __call__(self) -> None:
        i = self.k % len(self.frames)
        self.k += 1
        if i == 0:
            self.loc.reset(self.poses[0])
        pts, nrm = self.points(i)
        inc = self.poses[i] - self.poses[i - 1] if i else np.zeros(3)
        self.loc.predict(inc)
        self.loc.update(pts, nrm)
        self.loc.estimate()


if __name__ == "__main__":
    import json

    res: dict = {}
    bench_scans(res, "--quick" in sys.argv)
    print(json.dumps(res, indent=2))
