"""Benchmark of rerun logging in the closed loop (logging may slow the loop by at most 20%).

- ``closed_loop_frame``: one frame of the demo scenario's closed loop (physics, render,
  Kinect noise, FSPF, CGR, avoidance and navigation) with no recording: the run's wall
  time over its frames, for a 20 s stretch of the demo (8 s with ``--quick``).
- ``closed_loop_frame_rrd``: the same run (same seed, so the same frames) writing an .rrd
  at the demo's settings (heavy items every ``report.rrd_every`` frames). Its target is
  1.2 x the unrecorded frame's median; its ``realtime_factor`` (target 2.5) is the demo's
  real-time factor with the recording on. The runner's own measurement (time spent logging
  over the rest of the loop) goes to stderr.

Samples alternate between the two so that load drifts on a shared machine hit both.
Run alone: ``.venv/bin/python bench/viz_bench.py [--quick]``.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import Result, entry  # noqa: E402

#: Logging may slow the loop by at most this fraction.
MAX_OVERHEAD = 0.2


def bench_viz(results: dict[str, Result], quick: bool) -> None:
    from sim.experiments.runner import run_scenario
    from sim.scenario import SCENARIOS_DIR, load_scenario

    duration = 8.0 if quick else 20.0
    scn = load_scenario(SCENARIOS_DIR / "demo.toml", [f"mission.max_duration_s={duration}", "report.figures=false"])
    warm = load_scenario(SCENARIOS_DIR / "demo.toml", ["mission.max_duration_s=1.0", "report.figures=false"])
    plain: list[float] = []
    logged: list[float] = []
    shares: list[float] = []
    rtf: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        run_scenario(warm, out / "warm", seed=scn.seed, rrd=out / "warm" / "w.rrd", progress=False)  # JIT and GL warm-up
        for k in range(1 if quick else 3):
            rep = run_scenario(scn, out / f"plain{k}", seed=scn.seed, progress=False)
            m = rep["metrics"]
            plain.append(1e3 * m["wall_time_s"] / max(m["frames"], 1))
            rep = run_scenario(scn, out / f"rrd{k}", seed=scn.seed, rrd=out / f"rrd{k}" / "run.rrd", progress=False)
            m = rep["metrics"]
            logged.append(1e3 * (m["wall_time_s"] + m["recording_flush_s"]) / max(m["frames"], 1))
            rtf.append(m["realtime_factor"])
            shares.append(m["logging_overhead"])
            size_mb = (out / f"rrd{k}" / "run.rrd").stat().st_size / 1e6
    base = entry(plain)
    results["closed_loop_frame"] = base
    results["closed_loop_frame_rrd"] = entry(logged, target=round((1 + MAX_OVERHEAD) * base["median_ms"], 3))
    # The demo's real-time factor with the recording on (simulated over wall time): a
    # wall-clock figure, so it is measured here and never asserted by a test.
    results["closed_loop_frame_rrd"].update(realtime_factor=round(float(sorted(rtf)[len(rtf) // 2]), 3), realtime_factor_target=2.5)
    ratio = entry(logged)["median_ms"] / base["median_ms"] - 1
    print(
        f"bench viz: recording costs {100 * ratio:+.1f}% of the loop (runner's own measure: "
        f"{100 * sorted(shares)[len(shares) // 2]:.1f}%); {size_mb:.1f} MB for {duration:.0f} s at rrd_every={scn.report.rrd_every}",
        file=sys.stderr,
    )


if __name__ == "__main__":
    from run import print_table

    res: dict[str, Result] = {}
    bench_viz(res, "--quick" in sys.argv)
    print_table(res)
