"""Headless end-to-end runs of the demo scenario (closed loop, report contract, files)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from sim.cli import main
from sim.experiments.metric_names import METRICS
from sim.experiments.runner import run_scenario
from sim.scenario import SCENARIOS_DIR, load_scenario
from tests.helpers import interrupt

REQUIRED_METRICS = {"frames", "distance_m", "duration_s", "collisions", "waypoints_reached", "waypoints_failed", "realtime_factor"}


def _short_demo(extra: list[str] | None = None):
    return load_scenario(
        SCENARIOS_DIR / "demo.toml",
        ["map.name=\"small_floor\"", "mission.max_duration_s=6.0", "actors.random_furniture=1", "actors.random_people=1"] + (extra or []),
    )


def test_short_run_writes_the_report_contract(tmp_path: Path) -> None:
    rep = run_scenario(_short_demo(), tmp_path, seed=3, progress=False)
    on_disk = json.loads((tmp_path / "report.json").read_text())
    assert on_disk == json.loads(json.dumps(rep))
    assert on_disk["scenario"] == "demo" and on_disk["seed"] == 3
    assert REQUIRED_METRICS <= set(on_disk["metrics"])
    # Every metric is in the documented list an [expect] table may name.
    assert set(on_disk["metrics"]) <= set(METRICS), set(on_disk["metrics"]) - set(METRICS)
    assert on_disk["expect"] == {"passed": True, "checks": []}
    assert isinstance(on_disk["paper"], dict)
    assert {"physics", "render", "noise"} <= set(on_disk["timing_ms"])
    m = on_disk["metrics"]
    assert m["waypoints_reached"] + m["waypoints_failed"] + m["waypoints_unvisited"] == len(on_disk["waypoints"])
    assert m["distance_m"] > 1.0  # it drove
    # CGR localization ran on FSPF points every frame and tracked the robot.
    for key in ("loc_error_mean_m", "loc_error_median_m", "loc_error_p95_m", "loc_error_max_m", "resets"):
        assert key in m, key
    assert m["loc_error_max_m"] < 0.3 and m["resets"] == 0
    assert "localization" in on_disk["timing_ms"]
    est = np.loadtxt(tmp_path / "trajectory_estimate.tum")
    assert est.shape == (m["frames"] + 1, 8)
    tum = np.loadtxt(tmp_path / "trajectory_truth.tum")
    assert tum.shape[1] == 8 and len(tum) == m["frames"] + 1
    np.testing.assert_allclose(np.linalg.norm(tum[:, 4:], axis=1), 1.0, atol=1e-6)
    assert (tmp_path / "trajectory.png").stat().st_size > 1000


def test_same_seed_same_run(tmp_path: Path) -> None:
    a = run_scenario(_short_demo(["mission.max_duration_s=2.0"]), tmp_path / "a", seed=11, progress=False)
    b = run_scenario(_short_demo(["mission.max_duration_s=2.0"]), tmp_path / "b", seed=11, progress=False)
    assert (tmp_path / "a" / "trajectory_truth.tum").read_text() == (tmp_path / "b" / "trajectory_truth.tum").read_text()
    assert a["metrics"]["distance_m"] == b["metrics"]["distance_m"]


def test_interrupted_run_still_writes_its_report(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import sim.simulator.kinect as kinect

    calls = {"n": 0}
    real = kinect.apply_kinect_noise

    def flaky(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 20:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(kinect, "apply_kinect_noise", flaky)
    rep = run_scenario(_short_demo(), tmp_path, seed=1, progress=False)
    assert rep["interrupted"] is True
    assert rep["metrics"]["frames"] == 18  # call 1 is the frame captured before the loop
    assert json.loads((tmp_path / "report.json").read_text())["interrupted"] is True


def _fail_at_call(monkeypatch: pytest.MonkeyPatch, n: int, exc: Exception | None = None) -> None:
    """Make the runner's localization check raise ``exc`` (a bug's ZeroDivisionError) on
    its ``n``-th call: mid-frame, inside the stack's step on the frame, after the frame's
    physics and before its records."""
    import sim.experiments.loop as loop

    calls = {"n": 0}
    real = loop.check_localization

    def failing(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == n:
            raise exc if exc is not None else ZeroDivisionError("a bug in the loop\nsecond line")
        return real(*args, **kwargs)

    monkeypatch.setattr(loop, "check_localization", failing)


def test_a_run_that_stops_on_an_error_keeps_its_report(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from sim.experiments.kinds import RunCrashed

    _fail_at_call(monkeypatch, 40)
    with pytest.raises(RunCrashed) as info:
        run_scenario(_short_demo(["report.figures=true"]), tmp_path, seed=1, progress=False)
    msg = str(info.value)
    assert "\n" not in msg and "ZeroDivisionError: a bug in the loop" in msg and "crash.txt" in msg
    assert info.value.report_path == str(tmp_path / "report.json")
    rep = json.loads((tmp_path / "report.json").read_text())
    assert rep["interrupted"] is True
    err = rep["error"]
    assert err["type"] == "ZeroDivisionError" and err["message"] == "a bug in the loop" and err["frame"] == 39
    assert 1.2 < err["t"] < 1.4 and err["distance_m"] == pytest.approx(rep["metrics"]["distance_m"], abs=1e-3)
    trace = (tmp_path / "crash.txt").read_text()
    assert trace.startswith("Traceback") and "failing" in trace and "second line" in trace
    # The failed frame's rows are dropped: every record ends on the last whole frame.
    m = rep["metrics"]
    assert m["frames"] == 39 and "loc_error_max_m" in m
    assert len(np.loadtxt(tmp_path / "trajectory_estimate.tum")) == 40
    assert len(np.loadtxt(tmp_path / "trajectory_truth.tum")) == 40
    assert (tmp_path / "trajectory.png").exists()


def test_ctrl_c_inside_the_stacks_step_ends_the_records_on_the_last_whole_frame(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C (or SIGTERM) landing in the stack's step after the runner's check has
    recorded the frame's estimate, before the loop records the frame's time: the run
    stops as interrupted and its trajectories end on the same last whole frame."""
    import sim.experiments.loop as loop

    calls = {"n": 0}
    real = loop.check_localization

    def then_interrupted(*args, **kwargs):
        calls["n"] += 1
        out = real(*args, **kwargs)
        if calls["n"] == 30:
            raise KeyboardInterrupt
        return out

    monkeypatch.setattr(loop, "check_localization", then_interrupted)
    rep = run_scenario(_short_demo(), tmp_path, seed=1, progress=False)
    assert rep["interrupted"] is True and rep["error"] is None and rep["metrics"]["frames"] == 29
    assert len(np.loadtxt(tmp_path / "trajectory_estimate.tum")) == len(np.loadtxt(tmp_path / "trajectory_truth.tum")) == 30


def test_a_sweep_trial_that_stops_on_an_error_names_its_seed(monkeypatch: pytest.MonkeyPatch) -> None:
    from sim.experiments.mission import trial

    _fail_at_call(monkeypatch, 5)
    with pytest.raises(RuntimeError, match=r"^seed 11: the run stopped at t = .* on an error: ZeroDivisionError: a bug in the loop$"):
        trial(_short_demo(), {"id": "trial-0000", "seed": 11})


def test_a_users_mistake_found_on_the_way_is_still_a_one_line_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """An InputError raised inside the loop (a waypoint the user's map has no path to)
    keeps the report of what finished and stays the CLI's one-line user error (exit 2)."""
    from autonomy.maps.planner import NoPathError

    _fail_at_call(monkeypatch, 10, NoPathError("navigation graph: no path from node 3 to node 9"))
    out = tmp_path / "out"
    code = main(["run", "scenarios/demo.toml", "--out", str(out), "--set", "map.name=\"small_floor\"", "--set", "report.progress=false"])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("depthnav: error: navigation graph: no path from node 3 to node 9 (the run stopped at t = ")
    assert str(out / "report.json") in err[0]
    rep = json.loads((out / "report.json").read_text())
    assert rep["error"]["type"] == "NoPathError" and rep["metrics"]["frames"] == 9


def test_a_run_without_an_error_reports_none(tmp_path: Path) -> None:
    rep = run_scenario(_short_demo(["mission.max_duration_s=1.0"]), tmp_path, seed=1, progress=False)
    assert rep["error"] is None and not (tmp_path / "crash.txt").exists()


def test_the_cli_says_in_one_line_where_a_failed_run_left_its_report(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _fail_at_call(monkeypatch, 10)
    out = tmp_path / "out"
    code = main(["run", "scenarios/demo.toml", "--out", str(out), "--set", "map.name=\"small_floor\"", "--set", "report.progress=false"])
    assert code == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("depthnav: demo: the run stopped at t = ")
    assert str(out / "report.json") in err[0] and json.loads((out / "report.json").read_text())["error"]["frame"] == 9


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_background_run_stops_on_a_signal_and_keeps_its_report(tmp_path: Path, sig: int) -> None:
    """A run started in the background by a shell without job control inherits SIGINT
    ignored; ``kill -INT`` (or ``kill``) still stops it as Ctrl-C does: report kept."""
    root = Path(__file__).resolve().parents[2]
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "sim.cli", "run", str(SCENARIOS_DIR / "demo.toml"), "--out", str(out)]
    proc = subprocess.Popen(
        cmd, cwd=root, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),
    )
    assert proc.stdout is not None
    started = proc.stdout.readline()  # the first line comes once the world is built
    assert "depth camera" in started, started
    t0 = time.time()
    rest = interrupt(proc, sig, lambda: time.time() - t0 > 3.0)
    assert proc.returncode == 128 + sig, rest  # 130 for SIGINT, 143 for SIGTERM (the shells' convention)
    rep = json.loads((out / "report.json").read_text())
    assert rep["interrupted"] is True and rep["metrics"]["frames"] > 0


def test_a_killed_run_keeps_its_last_checkpoint(tmp_path: Path) -> None:
    """SIGKILL cannot be caught: what a run killed that way keeps is the report of its
    last checkpoint, whole (never a half-written file), with the metrics and events to
    then, marked interrupted."""
    root = Path(__file__).resolve().parents[2]
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "sim.cli", "run", str(SCENARIOS_DIR / "demo.toml"), "--out", str(out),
           "--set", 'map.name="small_floor"', "--set", "report.checkpoint_s=0.5", "--set", "report.progress=false"]
    proc = subprocess.Popen(cmd, cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)

    def two_checkpoints() -> bool:
        try:
            return json.loads((out / "report.json").read_text())["checkpoint"]["t"] >= 1.0
        except (OSError, ValueError, KeyError):
            return False

    interrupt(proc, signal.SIGKILL, two_checkpoints)
    assert proc.returncode == -signal.SIGKILL
    rep = json.loads((out / "report.json").read_text())
    assert rep["interrupted"] is True and rep["scenario"] == "demo"
    c, m = rep["checkpoint"], rep["metrics"]
    assert c["t"] >= 1.0 and m["frames"] == c["frame"] > 0 and m["duration_s"] == pytest.approx(c["t"], abs=1e-3)
    assert m["distance_m"] == pytest.approx(c["distance_m"], abs=1e-3) and rep["resources"]["rss_peak_mb"] > 0


def test_the_final_report_replaces_the_checkpoints(tmp_path: Path) -> None:
    rep = run_scenario(_short_demo(["mission.max_duration_s=1.5", "report.checkpoint_s=0.5"]), tmp_path, seed=1, progress=False)
    on_disk = json.loads((tmp_path / "report.json").read_text())
    assert "checkpoint" not in rep and "checkpoint" not in on_disk and on_disk["interrupted"] is False
    assert on_disk["metrics"]["frames"] == rep["metrics"]["frames"] > 0 and not (tmp_path / "report.json.tmp").exists()


def test_a_checkpoint_that_cannot_be_written_does_not_stop_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import sim.experiments.runner as runner

    calls = []

    def full_disk(*args) -> None:
        calls.append(args)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(runner, "write_checkpoint", full_disk)
    rep = run_scenario(_short_demo(["mission.max_duration_s=1.5", "report.checkpoint_s=0.5"]), tmp_path, seed=1, progress=False)
    assert len(calls) == 1 and rep["interrupted"] is False and rep["metrics"]["duration_s"] >= 1.4
    err = [ln for ln in capsys.readouterr().err.splitlines() if "checkpoint" in ln]
    assert err == ["demo: could not write the checkpoint report.json ([Errno 28] No space left on device); the run goes on without checkpoints"]


def test_checkpoints_do_not_change_the_run(tmp_path: Path) -> None:
    reps = {}
    for every in (0.0, 0.2):
        out = tmp_path / str(every)
        reps[every] = run_scenario(_short_demo(["mission.max_duration_s=2.0", f"report.checkpoint_s={every}"]), out, seed=4, progress=False)
        reps[every]["truth"] = (out / "trajectory_truth.tum").read_text()
    keep = ("frames", "distance_m", "loc_error_mean_m", "loc_error_max_m", "collisions")
    assert {k: reps[0.0]["metrics"][k] for k in keep} == {k: reps[0.2]["metrics"][k] for k in keep}
    assert reps[0.0]["truth"] == reps[0.2]["truth"] and reps[0.0]["recovery"] == reps[0.2]["recovery"]


@pytest.mark.slow
def test_demo_scenario_end_to_end_via_cli(tmp_path: Path) -> None:
    """The README's demo (the long run shortened to 300 m), headless through the CLI with
    a rerun recording; cut to 60 m here (the 200 m long-run test covers the distance)."""
    out = tmp_path / "demo"
    rrd = out / "demo.rrd"
    assert main(["run", "scenarios/demo.toml", "--out", str(out), "--rrd", str(rrd), "--set", "mission.target_distance_m=60"]) == 0
    rep = json.loads((out / "report.json").read_text())
    m = rep["metrics"]
    assert m["distance_m"] >= 60.0 and m["waypoints_reached"] >= 2 and m["waypoints_failed"] == 0
    assert m["collisions"] == 0 and m["resets"] == 0
    assert m["realtime_factor"] > 0.0  # its size is a wall-clock figure: measured by make bench
    assert 0.0 < m["logging_overhead"] and m["recording_flush_s"] >= 0.0
    assert rep["paper"]["resets_per_km"] == 0.75
    assert rrd.stat().st_size > 100_000


def test_collision_incidents_group_contact_events() -> None:
    from sim.experiments.metrics import collision_incidents

    ev = [
        {"t": 1.0, "bodies": ["person_0"]}, {"t": 1.1, "bodies": ["person_0"]}, {"t": 3.9, "bodies": ["person_0"]},
        {"t": 2.0, "bodies": ["world"]}, {"t": 7.5, "bodies": ["person_0"]}, {"t": 7.6, "bodies": ["person_1"]},
    ]
    assert collision_incidents(ev) == 4  # person_0 at 1-3.9 s, the wall, person_0 again, person_1
    assert collision_incidents([]) == 0
    assert collision_incidents(ev, gap_s=10.0) == 3


def test_the_depth_backend_line_names_the_fix_for_the_slow_fallback():
    from sim.experiments.loop import depth_backend_line

    assert "OpenGL" in depth_backend_line("gl")
    slow = depth_backend_line("raycast")
    assert "20x slower" in slow and "make gl" in slow and "\n" not in slow


def test_resources_report_memory_and_frame_time_at_both_ends():
    from types import SimpleNamespace

    from sim.experiments.memory import resident_mb
    from sim.experiments.metrics import ENDS_FRAMES, resources
    from sim.experiments.site import STAGES

    n = 2 * ENDS_FRAMES + 500
    timing = {k: [0.001] * n for k in STAGES}
    timing["render"] = [0.002] * (ENDS_FRAMES + 500) + [0.004] * ENDS_FRAMES  # the last frames slower
    r = resources(SimpleNamespace(rss_mb=[(1, 300.0, 0.0), (901, 320.0, 20.0), (1801, 310.0, 40.0)], timing=timing, distance_m=40.0))
    assert r["rss_start_mb"] == 300.0 and r["rss_end_mb"] == 310.0 and r["rss_peak_mb"] == 320.0
    assert r["rss_by_distance"] == [[0.0, 300.0], [20.0, 320.0], [40.0, 310.0]]
    assert "rss_first_km_mb" not in r  # a short run has no first and last kilometre
    # A 3 km run: the medians over the first and the last kilometre.
    rss = [(1 + 900 * k, 300.0 + k, 100.0 * k) for k in range(31)]
    r = resources(SimpleNamespace(rss_mb=rss, timing=timing, distance_m=3000.0))
    assert r["rss_first_km_mb"] == 305.0 and r["rss_last_km_mb"] == 325.0
    assert r["frame_ms_start"] == pytest.approx(1e3 * (0.001 * (len(STAGES) - 1) + 0.002))
    assert r["frame_ms_end"] > r["frame_ms_start"]
    assert 10.0 < resident_mb() < 1e5


def test_the_incident_figure_draws_the_furniture_the_contact_names(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    from sim.experiments.blackbox import _draw_furniture, render_incidents
    from sim.simulator.actors import Furniture

    pieces = (Furniture("table", 1.0, 2.0, 0.5), Furniture("cabinet", 3.0, 2.0, 0.0))
    ax = Figure().add_subplot()
    _draw_furniture(ax, pieces)
    assert len(ax.patches) == 2 and {t.get_text() for t in ax.texts} == {"table 0", "cabinet 1"}
    inc = {"event": {"t": 5.0, "x": 1.5, "y": 2.0, "bodies": ["furniture_0"]}, "trace": []}
    walls = np.array([[0.0, 0.0, 4.0, 0.0]])
    assert render_incidents([inc], walls, tmp_path / "i.png", furniture=pieces).stat().st_size > 0


def test_per_frame_records_cost_bytes_not_objects(tmp_path: Path) -> None:
    """A 4 km run is 200,000 frames: what the loop keeps per frame must be raw values
    (about 130 bytes), not Python objects (about 800)."""
    from sim.experiments.loop import drive
    from sim.experiments.site import build_run

    run = build_run(_short_demo(["mission.max_duration_s=2.0"]), seed=5)
    drive(run, None, progress=False)
    per_frame = [run.times, run.truth, run.estimates, run.loc_errors, run.heading_errors, run.fspf_counts, *run.timing.values()]
    assert all(len(c) >= run.frames for c in per_frame)
    assert sum(_deep_size(c) for c in per_frame) / run.frames < 200
    assert _deep_size([np.zeros(3) for _ in range(100)]) / 100 > 100  # what a list of poses costs
    run.camera.close()


def _deep_size(obj) -> int:
    """Bytes an object holds, counting a container's items (a column's rows)."""
    from sim.experiments.columns import Column

    if isinstance(obj, Column):
        return obj.values.nbytes
    if isinstance(obj, (list, tuple)):
        return sys.getsizeof(obj) + sum(_deep_size(x) for x in obj)
    return sys.getsizeof(obj)


def test_the_trajectory_figure_keeps_fault_failures_apart_from_the_papers_resets() -> None:
    from sim.experiments.report import failure_markers, failures_title

    failures = [
        {"x": 1.0, "y": 2.0, "fault": None},
        {"x": 3.0, "y": 4.0, "fault": "kidnap"},
        {"x": 5.0, "y": 6.0, "fault": "slip"},
    ]
    m = failure_markers(failures)
    np.testing.assert_array_equal(m["resets (the paper's count)"], [[1.0, 2.0]])
    np.testing.assert_array_equal(m["failures from faults"], [[3.0, 4.0], [5.0, 6.0]])
    assert list(failure_markers(failures[1:])) == ["failures from faults"]
    assert failure_markers([]) == {}
    # A robot started without its pose is neither a reset nor a fault's failure.
    searching = {"x": 7.0, "y": 8.0, "fault": "unknown start"}
    np.testing.assert_array_equal(failure_markers([searching])["unknown start"], [[7.0, 8.0]])
    assert failures_title(failures + [searching]) == "1 resets (and 2 failures from faults, 1 unknown start)"
    assert failures_title([]) == "0 resets"


def test_the_trace_window_writes_each_of_its_frames_as_the_run_saw_it(tmp_path: Path) -> None:
    rep = run_scenario(_short_demo(["mission.max_duration_s=3.0", "report.trace_s=[1.01, 2.01]", "report.figures=false"]), tmp_path, seed=3, progress=False)
    assert rep["files"]["trace"] == "trace.jsonl"
    rows = [json.loads(line) for line in (tmp_path / "trace.jsonl").read_text().splitlines()]
    truth = np.loadtxt(tmp_path / "trajectory_truth.tum")
    est = np.loadtxt(tmp_path / "trajectory_estimate.tum")
    inside = (truth[:, 0] >= 1.01) & (truth[:, 0] <= 2.01)
    # One record per frame of the window (30 frames a second), in order.
    assert len(rows) == int(inside.sum()) and 29 <= len(rows) <= 31
    np.testing.assert_allclose([r["t"] for r in rows], truth[inside, 0], atol=1e-4)
    # Its poses are the trajectory files' (TUM: x y z, quaternion; yaw from qz, qw).
    np.testing.assert_allclose([r["truth"][:2] for r in rows], truth[inside, 1:3], atol=1e-3)
    np.testing.assert_allclose([r["estimate"][:2] for r in rows], est[inside, 1:3], atol=1e-3)
    yaw = 2.0 * np.arctan2(est[inside, 6], est[inside, 7])
    np.testing.assert_allclose(np.cos([r["estimate"][2] for r in rows]), np.cos(yaw), atol=1e-3)
    for r in rows:
        assert abs(r["error_m"] - float(np.hypot(r["estimate"][0] - r["truth"][0], r["estimate"][1] - r["truth"][1]))) < 1e-3
        assert r["health"] in ("ok", "blind", "lost", "relocalizing") and r["nav_state"] and len(r["command"]) == 3
        assert r["points_2d"] >= 0 and "explained_fast" in r["monitor"]
    assert any(r["points_2d"] > 0 for r in rows)
    # CGR's update on each frame it ran: the points it was given and what it did with them.
    updated = [r for r in rows if "cgr" in r]
    assert updated and all(r["cgr"]["points"] == r["points_2d"] for r in updated)
    assert {"used_points", "shared", "dropped_points", "unscored_tail", "observation"} <= set(updated[0]["cgr"])


@pytest.mark.parametrize("window", ["[2.0, 1.0]", "[1.0]", "[-1.0, 2.0]", "[1.0, nan]"])
def test_a_bad_trace_window_is_a_one_line_error(window: str) -> None:
    from autonomy.common.errors import InputError

    with pytest.raises(InputError, match=r"report\.trace_s(\[1\])?.* expected"):
        _short_demo([f"report.trace_s={window}"])


def test_an_interrupt_inside_a_numba_kernel_is_an_interruption(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A signal handled while a numba kernel runs surfaces as a SystemError caused by the
    KeyboardInterrupt: the run is interrupted (report kept), not crashed."""
    import sim.experiments.loop as loop

    def interrupted_kernel(run, recorder) -> bool:
        # As numba raises it: the interrupt wrapped in SystemErrors three levels deep.
        try:
            try:
                try:
                    raise KeyboardInterrupt
                except KeyboardInterrupt as k:
                    raise SystemError("_numba_unpickle returned a result with an exception set") from k
            except SystemError as e1:
                raise SystemError("_numba_unpickle returned a result with an exception set") from e1
        except SystemError as e2:
            raise SystemError("CPUDispatcher(update_memory) returned a result with an exception set") from e2

    monkeypatch.setattr(loop, "tick", interrupted_kernel)
    rep = run_scenario(_short_demo(["mission.max_duration_s=1.0"]), tmp_path, seed=1, progress=False)
    assert rep["interrupted"] is True and rep["error"] is None and not (tmp_path / "crash.txt").exists()


def test_a_system_error_without_an_interrupt_is_a_crash(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A SystemError with no KeyboardInterrupt down its chain is a bug: crash report written."""
    import sim.experiments.loop as loop
    from sim.experiments.kinds import RunCrashed

    def broken_kernel(run, recorder) -> bool:
        try:
            raise ValueError("bad array")
        except ValueError as v:
            raise SystemError("CPUDispatcher(update_memory) returned a result with an exception set") from v

    monkeypatch.setattr(loop, "tick", broken_kernel)
    with pytest.raises(RunCrashed, match="SystemError"):
        run_scenario(_short_demo(["mission.max_duration_s=1.0"]), tmp_path, seed=1, progress=False)
    assert "ValueError: bad array" in (tmp_path / "crash.txt").read_text()


def test_blind_driving_counts_the_metres_cgr_dead_reckoned_and_the_longest_stretch() -> None:
    from types import SimpleNamespace

    from autonomy.localization.cgr import UpdateStats
    from sim.experiments.accounting import note_blind

    seen, unseen = UpdateStats(observation=True), UpdateStats(observation=False)
    out = SimpleNamespace(localizing=True, relocalizing=False, cgr_stats=None)
    run = SimpleNamespace(out=out, driven_by_own_stack=False, tracked_m=0.0, blind_m=0.0, blind_stretch_m=0.0, blind_stretch_max_m=0.0)
    # (what CGR did, relocalizing, metres): 1 m seen, 3 m blind (a refused frame among
    # them), 1 m seen, 2 m blind, 4 m relocalizing (the search's, not CGR's), 2.5 m blind.
    frames = [(seen, False, 1.0), (unseen, False, 1.0), (None, False, 1.0), (unseen, False, 1.0), (seen, False, 1.0),
              (unseen, False, 2.0), (None, True, 4.0), (unseen, False, 2.5)]
    for stats, reloc, metres in frames:
        out.cgr_stats, out.relocalizing = stats, reloc
        note_blind(run, metres)
    assert run.tracked_m == 9.5 and run.blind_m == 7.5
    assert run.blind_stretch_max_m == 3.0 and run.blind_stretch_m == 2.5
    # No localizer (a ground-truth follower): nothing counted.
    out.localizing = False
    note_blind(run, 5.0)
    assert run.tracked_m == 9.5
