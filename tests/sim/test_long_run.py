"""The paper's long-run trial (BV2012, VI-B), shortened to 200 m for CI: the whole
stack in the loop on the corridor building with people and furniture."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim.experiments.runner import run_scenario
from sim.scenario import SCENARIOS_DIR, load_scenario


@pytest.mark.slow
def test_a_200_m_long_run_has_no_collisions_and_no_resets(tmp_path: Path) -> None:
    scn = load_scenario(SCENARIOS_DIR / "long_run.toml", ["mission.target_distance_m=200", "report.figures=false"])
    rep = run_scenario(scn, tmp_path, progress=False)
    m = rep["metrics"]
    assert m["distance_m"] >= 200.0
    assert m["collisions"] == 0, rep["collision_events"]
    assert m["resets"] == 0
    assert m["waypoints_failed"] == 0 and m["waypoints_reached"] >= 5
    assert m["loc_error_mean_m"] < 0.1
    assert (tmp_path / "trajectory_truth.tum").is_file() and (tmp_path / "trajectory_estimate.tum").is_file()
