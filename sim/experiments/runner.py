"""Closed-loop runs of mission scenarios: build the site, drive the loop, report.

:func:`run_scenario` is the entry the ``mission`` kind, the CLI and the tests call. The
parts: :mod:`sim.experiments.site` sets up the world and the robot stack from the
scenario and seed, :mod:`sim.experiments.loop` drives the closed loop (one tick per
Kinect frame), :mod:`sim.experiments.accounting` keeps what each frame adds,
:mod:`sim.experiments.metrics` and :mod:`sim.experiments.report` turn it into
``report.json`` (the contract in the README), the trajectory figure and the true and
estimated trajectories in TUM format, and :mod:`sim.viz.run_log` writes the rerun
recording on request. Ctrl-C stops a run early and still writes what it measured; so
does an error inside the loop, which then also writes its traceback to ``crash.txt``
and raises :class:`sim.experiments.kinds.RunCrashed`.
"""

from __future__ import annotations

import time
from pathlib import Path

from autonomy.maps.planner import path_points
from sim.experiments.expect import check
from sim.experiments.kinds import stopped
from sim.experiments.loop import drive
from sim.experiments.report import crash_report, finish_report, write_checkpoint, write_report
from sim.experiments.site import build_run
from sim.rosbag.run_bag import open_run_bag
from sim.scenario import Scenario
from sim.viz.run_log import RunLogger


def run_scenario(
    scn: Scenario,
    out_dir: str | Path,
    *,
    seed: int | None = None,
    rrd: str | Path | None = None,
    spawn: bool = False,
    progress: bool | None = None,
    bag: str | Path | None = None,
    bag_depth: str = "32FC1",
) -> dict:
    """Run a scenario headless and write its report; returns the report dict. ``bag``:
    also write the run as a rosbag2 in MCAP storage (:mod:`sim.rosbag.run_bag`), its
    depth images as ``bag_depth`` (``32FC1`` metres, exact; ``16UC1`` millimetres)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    seed = scn.seed if seed is None else int(seed)
    if spawn:
        from sim.viz.viewer import viewer_executable

        viewer_executable()  # no display or no viewer: one line now, not a hang later
    run = build_run(scn, seed)
    recorder = None
    if rrd or spawn:
        building = run.building
        recorder = RunLogger.open(
            rrd, spawn, scn=scn, seed=seed, vectormap=building.vectormap, navgraph=building.navgraph, furniture=run.furniture,
            waypoints_xy=path_points(building.navgraph, run.mission.waypoints),
        )
    if bag is not None:
        run.bag = open_run_bag(run, bag, bag_depth)
    wall_start = time.perf_counter()
    try:
        interrupted = drive(run, recorder, progress, lambda: write_checkpoint(run, out, time.perf_counter() - wall_start))
    finally:
        if run.bag is not None:
            run.bag.close()
    wall = time.perf_counter() - wall_start
    try:
        if run.crash is None:
            report = finish_report(run, out, recorder, rrd, wall, interrupted)
        else:
            report = crash_report(run, out, recorder, rrd, wall)
    finally:
        run.camera.close()
    report["expect"] = check(scn.expect, report["metrics"])
    write_report(out / "report.json", report)
    if run.crash is not None:
        c = run.crash
        # A user's mistake found only on the way (a waypoint the user's map has no path
        # to) stays the one-line error, with where the finished part was kept.
        assert run.crash_exc is not None
        raise stopped(run.crash_exc, f"the run stopped at t = {c['t']:.2f} s (frame {c['frame']}, {c['distance_m']:.0f} m)", out / "report.json") from None
    return report
