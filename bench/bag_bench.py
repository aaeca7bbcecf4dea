"""Replay speed from a ROS 2 bag: ``depthnav replay`` on a bag the simulator wrote.

A short demo run is written as a bag once (``run_scenario(..., bag=...)``), then the
robot stack is replayed on it (:func:`sim.rosbag.replay.replay_bag`): reading and
decoding each depth image and the odometry, FSPF, CGR and the lost detection. The row
is the time per frame; the target is real time at the Kinect's 30 Hz.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from common import Result, entry

#: Real time at the Kinect's 30 frames a second.
REAL_TIME_MS = 1000.0 / 30.0


def bench_bag(results: dict[str, Result], quick: bool) -> None:
    from sim.experiments.runner import run_scenario
    from sim.rosbag.replay import replay_bag
    from sim.scenario import SCENARIOS_DIR, load_scenario

    seconds = 3.0 if quick else 10.0
    scn = load_scenario(SCENARIOS_DIR / "demo.toml", [f"mission.max_duration_s={seconds}", "report.figures=false"])
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "run.mcap"
        run_scenario(scn, Path(tmp) / "run", bag=bag, progress=False)
        replay_bag(bag, Path(tmp) / "warm")  # kernels compiled and caches filled first
        samples = []
        for k in range(1 if quick else 3):
            t0 = time.perf_counter()
            rep = replay_bag(bag, Path(tmp) / f"replay{k}")
            samples.append(1000.0 * (time.perf_counter() - t0) / rep["metrics"]["frames"])
    results["bag_replay_frame"] = entry(samples, target=REAL_TIME_MS)
