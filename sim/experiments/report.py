"""A mission run's outputs: ``report.json`` (the contract in the README), its checkpoints
while the run goes on, the report of a run stopped by an error, the true and estimated
trajectories in TUM format, the trajectory and incident figures and the trace."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from autonomy.maps.planner import path_points
from sim.config import to_dict
from sim.experiments.blackbox import render_incidents
from sim.experiments.kinds import write_crash
from sim.experiments.metrics import fault_report, resources, run_metrics
from sim.experiments.report_file import write_json
from sim.experiments.site import Run
from sim.experiments.trace import TRACE_FILE, write_trace
from sim.viz.run_log import RunLogger

#: Report schema version (bump when keys change meaning).
REPORT_VERSION = 1

#: The paper's figures for scenarios that reproduce one of its experiments (BV2012).
PAPER_FIGURES: dict[str, dict[str, float]] = {
    # VI-B: the long-run trial drove over 4 km with 3 localization resets.
    "long_run": {"distance_m": 4000.0, "resets": 3, "resets_per_km": 0.75},
    # The demo is that trial shortened; the paper's rate is the figure to compare.
    "demo": {"distance_m": 4000.0, "resets": 3, "resets_per_km": 0.75},
}

#: Labels of the trajectory figure's failure markers, by what the failure is put down to.
RESETS_LABEL, FAULTS_LABEL, UNKNOWN_START_LABEL = "resets (the paper's count)", "failures from faults", "unknown start"


def write_tum(path: Path, t: np.ndarray, poses: np.ndarray) -> None:
    """Trajectory in TUM format: ``timestamp x y z qx qy qz qw`` per line."""
    with open(path, "w", encoding="utf-8") as f:
        f.write("# timestamp x y z qx qy qz qw\n")
        for ti, p in zip(t, poses, strict=True):
            f.write(f"{ti:.6f} {p[0]:.6f} {p[1]:.6f} 0.000000 0.000000 0.000000 {math.sin(p[2] / 2):.9f} {math.cos(p[2] / 2):.9f}\n")


def write_report(path: Path, report: dict) -> None:
    """Write report.json whole or not at all (a kill mid-write leaves the one before)."""
    write_json(path, report)


def write_checkpoint(run: Run, out: Path, wall: float) -> None:
    """report.json of what has finished so far (``report.checkpoint_s``): the metrics,
    events and recovery records to this frame, marked interrupted, with where it was
    written; no figures or trajectories (the final report writes them)."""
    report = build_report(run, run_metrics(run, wall), {"report": "report.json"}, True)
    report["checkpoint"] = {"t": round(float(run.world.data.time), 4), "frame": run.frames, "distance_m": round(run.distance_m, 3)}
    write_report(out / "report.json", report)


def finish_report(run: Run, out: Path, recorder: RunLogger | None, rrd: str | Path | None, wall: float, interrupted: bool) -> dict:
    """Metrics, figures, trajectories and the recording's close: the report dict."""
    metrics = run_metrics(run, wall)
    if recorder is not None:
        metrics.update(recorder.close(float(np.sum(run.timing["viz"])), wall))
    files = write_outputs(run, out, metrics, rrd if recorder is not None else None)
    return build_report(run, metrics, files, interrupted)


def crash_report(run: Run, out: Path, recorder: RunLogger | None, rrd: str | Path | None, wall: float) -> dict:
    """The report of a run the loop stopped on an error, with the traceback in ``crash.txt``.
    The frame that failed is dropped, so every record ends on the last whole frame; if
    the full report cannot be made from what is left, a short one with the loop's counts
    is written instead of nothing."""
    assert run.crash is not None and run.crash_exc is not None
    write_crash(out, run.crash_exc)
    try:
        report = finish_report(run, out, recorder, rrd, wall, True)
    except Exception as exc:  # the state the error left may not be reportable; the counts are
        run.crash["report_error"] = f"{type(exc).__name__}: {exc}"
        report = {
            "version": REPORT_VERSION, "scenario": run.scn.name, "seed": run.seed, "interrupted": True,
            "metrics": {"frames": run.frames, "distance_m": round(run.distance_m, 4), "collisions": run.collisions,
                        "waypoints_reached": run.mission.reached, "wall_time_s": round(wall, 3)},
            "files": {},
        }
    report["error"] = run.crash
    return report


#: The trajectory figure's label for where the robot touched something.
CONTACTS_LABEL = "contacts"


def contact_markers(collision_log: list[dict]) -> dict[str, np.ndarray]:
    """Where the robot was at each contact's onset (none: no marker set)."""
    xy = [[c["x"], c["y"]] for c in collision_log]
    return {CONTACTS_LABEL: np.array(xy)} if xy else {}


def estimate_label(run: Run) -> str:
    """Whose belief the figure draws: CGR's, or a scenario's own driver's."""
    return "driver's estimate" if run.driven_by_own_stack else "CGR estimate"


def failure_markers(failures: list[dict]) -> dict[str, np.ndarray]:
    """The trajectory figure's markers for where localization failures started: the
    paper's resets (nothing injected behind them) apart from the failures a fault caused
    (a kidnapping is meant to make one) and the error of a robot started without its
    pose before it found itself; empty sets left out."""
    def label(f: dict) -> str:
        why = f.get("fault")
        return RESETS_LABEL if why is None else UNKNOWN_START_LABEL if why == "unknown start" else FAULTS_LABEL

    groups: dict[str, list[list[float]]] = {RESETS_LABEL: [], FAULTS_LABEL: [], UNKNOWN_START_LABEL: []}
    for f in failures:
        groups[label(f)].append([f["x"], f["y"]])
    return {name: np.array(xy) for name, xy in groups.items() if xy}


def failures_title(failures: list[dict]) -> str:
    """The figure title's count of failures: the paper's resets, and the others by kind."""
    n = {name: len(xy) for name, xy in failure_markers(failures).items()}
    others = [f"{n[k]} {k}" for k in (FAULTS_LABEL, UNKNOWN_START_LABEL) if k in n]
    return f"{n.get(RESETS_LABEL, 0)} resets" + (f" (and {', '.join(others)})" if others else "")


def waypoint_markers(run: Run, graph, truth: np.ndarray) -> dict[str, np.ndarray]:
    """The trajectory figure's start and end (of the truth) and the waypoints by outcome:
    reached, missed (a timeout or the wrong place) and not visited (the run ended first)."""
    reached = [e["waypoint"] for e in run.mission.events if e.get("status") == "reached"]
    missed = [e["waypoint"] for e in run.mission.events if e.get("status") not in (None, "reached")]
    later = list(run.mission.waypoints[run.mission.current :])
    out = {"start": truth[:1, :2], "end": truth[-1:, :2]}
    for name, nodes in (("waypoints reached", reached), ("waypoints missed", missed), ("waypoints not visited", later)):
        if nodes:
            out[name] = path_points(graph, nodes)
    return out


def write_outputs(run: Run, out: Path, metrics: dict, rrd: str | Path | None) -> dict[str, str]:
    """Trajectories (TUM), the trajectory figure, the incidents; the files written."""
    scn, graph, vm = run.scn, run.building.navgraph, run.building.vectormap
    files = {"report": "report.json", "trajectory_truth": "trajectory_truth.tum"}
    truth = np.array(run.truth)
    write_tum(out / files["trajectory_truth"], np.array(run.times), truth)
    if run.localizing:
        files["trajectory_estimate"] = "trajectory_estimate.tum"
        write_tum(out / files["trajectory_estimate"], np.array(run.times[: len(run.estimates)]), np.array(run.estimates))
    if scn.report.figures:
        from sim.viz.maps import render_map

        render_map(
            vm,
            out / "trajectory.png",
            graph,
            trajectories={"ground truth": truth[:, :2], **({estimate_label(run): np.array(run.estimates)[:, :2]} if run.localizing else {})},
            markers={**waypoint_markers(run, graph, truth), **failure_markers(run.failures), **contact_markers(run.world.collision_log)},
            marker_styles={"start": "o", "end": "s", "waypoints reached": "^", "waypoints missed": "v", "waypoints not visited": "D",
                           CONTACTS_LABEL: "*"},
            boxes=np.array([(f.x, f.y, f.yaw, f.dims[0], f.dims[1]) for f in run.furniture]).reshape(-1, 5),
            routes=[np.array(p.route) for p in run.people],
            title=f"{scn.name} (seed {run.seed}): {run.distance_m:.0f} m, {failures_title(run.failures)}, {run.collisions} contacts in {metrics['collision_incidents']} incidents",
        )
        files["trajectory_figure"] = "trajectory.png"
    if scn.report.trace_s:
        files["trace"] = TRACE_FILE
        write_trace(out / TRACE_FILE, run.trace)
    assert run.blackbox is not None
    if run.blackbox.incidents:
        files["incidents"] = "incidents.json"
        write_json(out / files["incidents"], {"seconds": scn.report.incident_seconds, "incidents": run.blackbox.incidents}, indent=None)
        if scn.report.figures:
            render_incidents(run.blackbox.incidents, np.asarray(vm.segments), out / "incidents.png", scn.robot.radius_m, furniture=run.furniture)
            files["incidents_figure"] = "incidents.png"
    if rrd:
        r, o = Path(rrd).resolve(), out.resolve()
        files["recording"] = str(r.relative_to(o)) if r.is_relative_to(o) else str(rrd)
    return files


def build_report(run: Run, metrics: dict, files: dict[str, str], interrupted: bool) -> dict:
    """The report.json contract (README)."""
    scn, graph, nav = run.scn, run.building.navgraph, run.out.plan
    assert nav is not None
    return {
        "version": REPORT_VERSION,
        "scenario": scn.name,
        "seed": run.seed,
        "interrupted": interrupted,
        "error": run.crash,
        "metrics": metrics,
        "paper": PAPER_FIGURES.get(scn.name, {}),
        "timing_ms": {k: round(float(np.median(v) * 1000.0) if v else 0.0, 4) for k, v in run.timing.items()},
        "resources": resources(run),
        "render_backend": run.camera.backend_name if run.camera._backend is not None else "none",
        "map": {"segments": run.building.vectormap.n_segments, "nodes": len(graph.nodes), "edges": len(graph.edges)},
        "actors": {"furniture": len(run.furniture), "people": len(run.people)},
        "waypoints": run.mission.waypoints,
        "navigation": {
            "states": run.nav_states, "replans": nav.replans, "recoveries": nav.recoveries, "near_field_frames": run.near_frames,
            "blocked_edges": nav.blocked_edges,
        },
        "events": run.mission.events,
        "recovery": {"events": list(run.out.events), "failures": run.failures, "faults": fault_report(run)},
        "collision_events": run.world.collision_log,
        "files": files,
        "config": {k: v for k, v in to_dict(scn).items() if k != "base_dir"},
    }
