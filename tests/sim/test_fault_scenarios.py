"""Closed-loop fault scenarios: one short headless run per fault kind (the runner injects
the fault, the robot stack recovers), and for kidnap, missing frames and tilt the same
run without the recovery, which must fail the same criterion."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

from sim.experiments.loop import drive
from sim.experiments.metric_names import METRICS
from sim.experiments.metrics import fault_report, run_metrics
from sim.experiments.runner import run_scenario
from sim.experiments.site import build_run
from sim.scenario import load_scenario
from tests.helpers import GL

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")]

#: Localization error (m) a recovered robot is back below (the runner's recovered_error_m).
OK_M = 0.5


def scenario(tmp_path: Path, fault: str, duration_s: float, extra: str = "", name: str = "fault"):
    """A short corridor_loop run with one fault event (``fault``: the event's TOML lines)
    and ``extra`` tables, no actors, random waypoints."""
    text = textwrap.dedent(
        f"""
        name = "{name}"
        seed = 1
        [map]
        name = "corridor_loop"
        [mission]
        kind = "waypoints"
        follower = "navigator"
        target_distance_m = 60.0
        max_duration_s = {duration_s}
        [odometry]
        translation_noise = 0.05
        rotation_noise = 0.05
        [report]
        figures = false
        progress = false
        [faults]
        [[faults.events]]
        """
    ) + textwrap.dedent(fault) + "\n" + textwrap.dedent(extra)
    path = tmp_path / f"{name}.toml"
    path.write_text(text, encoding="utf-8")
    return load_scenario(path)


def run(tmp_path: Path, fault: str, duration_s: float, seed: int, extra: str = "", name: str = "fault") -> dict:
    out = tmp_path / name
    out.mkdir()
    return run_scenario(scenario(out, fault, duration_s, extra, name), out, seed=seed, progress=False)


def the_fault(rep: dict, kind: str) -> dict:
    faults = [f for f in rep["recovery"]["faults"] if f["kind"] == kind and not f.get("skipped")]
    assert len(faults) == 1, rep["recovery"]["faults"]
    return faults[0]


def truth_track(tmp_path: Path, name: str) -> np.ndarray:
    """(t, x, y) rows of the run's true trajectory (its TUM file)."""
    rows = np.loadtxt(tmp_path / name / "trajectory_truth.tum", comments="#")
    return rows[:, :3]


def moved_m(track: np.ndarray, t0: float, t1: float) -> float:
    """Path length driven between t0 and t1."""
    seg = track[(track[:, 0] >= t0) & (track[:, 0] <= t1)]
    return float(np.sum(np.hypot(*np.diff(seg[:, 1:], axis=0).T))) if len(seg) > 1 else 0.0


# --------------------------------------------------------------------------- kidnap

# Seed 2: carried at 3 s to a distinctive spot of the building, so the relocalization
# decides in about 25 s (chosen among a few seeds for that).
KIDNAP = 'kind = "kidnap"\nat_s = 3.0'
KIDNAP_SEED = 2


def test_kidnap_is_noticed_and_relocalized_without_truth(tmp_path):
    rep = run(tmp_path, KIDNAP, 30.0, KIDNAP_SEED)
    f, m = the_fault(rep, "kidnap"), rep["metrics"]
    assert set(m) <= set(METRICS), set(m) - set(METRICS)  # the fault metrics are documented too
    assert f["noticed_t"] is not None and f["noticed_t"] >= f["t_start"]
    # The view jumped while the wheels stood still: noticed on the next frame.
    lost = [e for e in rep["recovery"]["events"] if e["event"] == "lost"]
    assert lost and lost[0]["why"] == "view jumped" and f["noticed_t"] - f["t_start"] < 0.1, (lost, f)
    assert f["ended_by"] == "robot" and f["recovered_t"] is not None
    assert m["truth_resets_needed"] == 0 and m["relocalizations"] >= 1
    # Where the robot was carried from and to, and where it was when the stack noticed,
    # read against the run's own true trajectory.
    track = truth_track(tmp_path, "fault")
    landed = track[np.searchsorted(track[:, 0], f["t_start"] + 1e-6)]
    assert np.allclose(f["truth_after"][:2], landed[1:], atol=0.05), (f, landed)
    assert math.hypot(f["truth_after"][0] - f["truth_before"][0], f["truth_after"][1] - f["truth_before"][1]) > 1.0
    # Noticed on the frame after the landing, where the robot still stands.
    assert np.allclose(f["truth_noticed"][:2], f["truth_after"][:2], atol=0.05), f
    assert f["error_after_m"] is not None and f["error_after_m"] < OK_M
    assert m["collisions"] == 0


def test_kidnap_without_recovery_stays_lost(tmp_path):
    rep = run(tmp_path, KIDNAP, 20.0, KIDNAP_SEED, "[recovery]\nenabled = false")
    f, m = the_fault(rep, "kidnap"), rep["metrics"]
    assert m["relocalizations"] == 0 and m["lost_alarms"] == 0
    assert f["recovered_t"] is None
    # Far from the truth (well past the reset threshold) when the run ends.
    assert rep["recovery"]["failures"] and rep["recovery"]["failures"][-1]["ended_by"] != "robot"


# --------------------------------------------------------------------------- camera faults

BLACKOUT = 'kind = "blackout"\nat_s = 3.0\nblackout_s = 4.0'


def forward_m(track: np.ndarray, t0: float, t1: float) -> float:
    """Distance driven forward (along the robot's heading) between t0 and t1, from the
    true trajectory (TUM rows t, x, y, z, qx, qy, qz, qw)."""
    seg = track[(track[:, 0] >= t0) & (track[:, 0] <= t1)]
    if len(seg) < 2:
        return 0.0
    th = 2.0 * np.arctan2(seg[:-1, 6], seg[:-1, 7])
    d = np.diff(seg[:, 1:3], axis=0)
    return float(np.sum(np.maximum(d[:, 0] * np.cos(th) + d[:, 1] * np.sin(th), 0.0)))


def test_blackout_robot_does_not_drive_into_what_it_cannot_see(tmp_path):
    # A blank frame is what a failed camera and a door right in front of it both give:
    # the near field reads it as blocked ahead, so the robot stops driving forward.
    rep = run(tmp_path, BLACKOUT, 12.0, 1, name="on")
    f, m = the_fault(rep, "blackout"), rep["metrics"]
    assert m["frames_invalid"] >= 110 and m["collisions"] == 0
    track = np.loadtxt(tmp_path / "on" / "trajectory_truth.tum", comments="#")
    assert forward_m(track, f["t_start"] - 3.0, f["t_start"]) > 0.5  # it was driving
    assert forward_m(track, f["t_start"] + 0.5, f["t_end"]) < 0.1
    assert f["error_after_m"] is not None and f["error_after_m"] < OK_M


NO_FRAMES = 'kind = "dropped"\nat_s = 3.0\nburst_s = 3.0\ndrop_probability = 1.0'


def test_no_frames_robot_stands_still_while_blind(tmp_path):
    rep = run(tmp_path, NO_FRAMES, 10.0, 1, name="on")
    f, m = the_fault(rep, "dropped"), rep["metrics"]
    assert m["frames_dropped"] >= 85 and m["blind_frames"] > 0 and m["collisions"] == 0
    blind = [e["t"] for e in rep["recovery"]["events"] if e["event"] == "blind"]
    assert blind and f["t_start"] <= blind[0] <= f["t_start"] + 1.0
    # From the blind alarm to the end of the burst the robot does not move.
    assert moved_m(truth_track(tmp_path, "on"), blind[0] + 0.5, f["t_end"]) < 0.05
    assert f["error_after_m"] is not None and f["error_after_m"] < OK_M


def test_no_frames_without_recovery_drives_blind(tmp_path):
    rep = run(tmp_path, NO_FRAMES, 10.0, 1, "[recovery]\nenabled = false", name="off")
    f = the_fault(rep, "dropped")
    assert rep["metrics"]["blind_frames"] == 0
    # It drives on (0.45 m in the 2 s; with the recovery it stands, under 0.05 m).
    assert moved_m(truth_track(tmp_path, "off"), f["t_start"] + 1.0, f["t_end"]) > 0.3


@pytest.mark.parametrize(
    ("kind", "counter"), [("dropped", "frames_dropped"), ("corrupt_nan", "frames_corrupt"), ("stale", "frames_stale")]
)
def test_bad_frames_are_not_used(tmp_path, kind, counter):
    rep = run(tmp_path, f'kind = "{kind}"\nat_s = 3.0\nburst_s = 3.0', 10.0, 1)
    f, m = the_fault(rep, kind), rep["metrics"]
    assert m[counter] > 0 and f["noticed_by"] is not None
    assert m["collisions"] == 0 and m["truth_resets_needed"] == 0
    assert f["error_after_m"] is not None and f["error_after_m"] < OK_M


def test_a_stuck_drivers_old_view_is_not_taken_for_the_stopped_robots(tmp_path):
    # Seed 3: the robot stops for the refused frames about 0.3 m from where the repeated
    # view was seen; taking that view for its own there, CGR pulled the belief back to it
    # and the first fresh frame after the burst disagreed with it (a false lost alarm).
    rep = run(tmp_path, 'kind = "stale"\nat_s = 3.0\nburst_s = 3.0', 9.0, 3)
    f, m = the_fault(rep, "stale"), rep["metrics"]
    assert m["frames_stale"] == 90  # every frame of the burst, 3 s at 30 frames a second
    assert m["lost_alarms"] == 0
    assert f["error_after_m"] is not None and f["error_after_m"] < 0.1


# --------------------------------------------------------------------------- odometry, mount

def test_slip_is_recovered_without_truth(tmp_path):
    # The relocalization may look round and search several times before it accepts a
    # place: 9-18 s after the slip on five of seeds 1-6 of this scenario. (On the sixth,
    # the push came while the robot turned in place facing a flat wall, the view check
    # agreed at 0.80, and the 0.57 m left along the corridor went unnoticed for 20 s.)
    rep = run(tmp_path, 'kind = "slip"\nat_s = 3.0', 25.0, 1)
    f, m = the_fault(rep, "slip"), rep["metrics"]
    assert m["truth_resets_needed"] == 0
    assert f["recovered_t"] is not None and f["error_after_m"] is not None and f["error_after_m"] < OK_M


TILT = 'kind = "tilt"\nat_s = 2.0\ntilt_deg = 4.0'


def test_tilt_mount_is_corrected(tmp_path):
    rep = run(tmp_path, TILT, 15.0, 1)
    f, m = the_fault(rep, "tilt"), rep["metrics"]
    corrected = [e for e in rep["recovery"]["events"] if e["event"] == "mount corrected"]
    assert corrected and f["t_start"] <= corrected[0]["t"] <= f["t_start"] + 3.0
    assert f["noticed_by"] == "mount corrected"
    assert m["loc_error_max_m"] < OK_M


def test_tilt_without_mount_check_goes_unnoticed(tmp_path):
    rep = run(tmp_path, TILT, 15.0, 1, "[recovery]\ncheck_mount = false")
    assert not [e for e in rep["recovery"]["events"] if e["event"] == "mount corrected"]
    assert the_fault(rep, "tilt")["noticed_by"] is None


# --------------------------------------------------------------------------- people, blockage

def test_crowd_without_collisions(tmp_path):
    rep = run(tmp_path, 'kind = "crowd"\nat_s = 2.0\ncrowd_size = 12\ncrowd_s = 15.0', 20.0, 1)
    f = the_fault(rep, "crowd")
    assert rep["actors"]["people"] >= 10
    assert rep["metrics"]["collisions"] == 0 and f["contacts"] == 0


def test_blockage_is_passed_by_replanning(tmp_path):
    scn = scenario(tmp_path, 'kind = "blockage"\nat_s = 2.0\nblockage_s = 0.0', 45.0)
    r = build_run(scn, 1)
    try:
        drive(r, None, False)
    finally:
        r.camera.close()
    f = [x for x in fault_report(r) if x["kind"] == "blockage"]
    assert len(f) == 1 and not f[0].get("skipped"), f
    assert r.out.plan is not None and r.out.plan.blocked_edges >= 1
    # It turned away and went the other way round (the loop is too long to finish in a
    # short test): it drove on for metres after the blockage appeared and ended far
    # from it, without contact.
    ev = [e for e in r.faults.events if e["kind"] == "blockage"][0]
    centre = np.asarray(ev["where"]["centre"], dtype=np.float64)
    times = np.asarray(r.times)
    track = np.asarray(r.truth)[times >= ev["t_start"]]
    assert float(np.sum(np.hypot(*np.diff(track[:, :2], axis=0).T))) > 10.0
    assert float(np.hypot(*(track[-1, :2] - centre))) > 5.0
    assert run_metrics(r, 1.0)["collisions"] == 0
