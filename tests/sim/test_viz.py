"""Rerun recordings of runs: they verify with rerun's own tooling and hold the expected entities."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from sim.experiments.metric_names import METRICS
from sim.experiments.runner import run_scenario
from sim.scenario import SCENARIOS_DIR, load_scenario
from tests.helpers import rerun_cli, rrd_chunks


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("viz")
    scn = load_scenario(
        SCENARIOS_DIR / "demo.toml",
        ['map.name="small_floor"', "mission.max_duration_s=3.0", "report.rrd_every=10", "actors.random_people=1", "actors.random_furniture=1"],
    )
    rep = run_scenario(scn, out, seed=2, rrd=out / "run.rrd", progress=False)
    assert rep["files"]["recording"] == "run.rrd"
    assert set(rep["metrics"]) <= set(METRICS), set(rep["metrics"]) - set(METRICS)  # the recording's too
    return out / "run.rrd"


@pytest.mark.skipif(rerun_cli() is None, reason="rerun CLI not installed")
def test_recording_verifies_and_holds_expected_entities(recording: Path) -> None:
    chunks = rrd_chunks(recording)
    counts = Counter(path for path, _ in chunks)
    columns = {path: cols for path, cols in chunks}
    for static in ("/world/map/walls", "/world/map/lines", "/world/map/navgraph/nodes", "/world/map/navgraph/edges", "/world/furniture", "/world/waypoints"):
        assert counts[static] == 1, static
    assert "Boxes3D:half_sizes" in columns["/world/map/walls"]
    assert "LineStrips3D:strips" in columns["/world/map/lines"]
    assert "DepthImage:buffer" in columns["/world/robot/camera/depth"]
    assert any("Pinhole:image_from_camera" in c for path, c in chunks if path == "/world/robot/camera")
    assert "Transform3D:translation" in columns["/world/robot"]
    # 3 s at 30 Hz, heavy items every 10th frame; rerun batches rows into chunks.
    assert sum(1 for path, _ in chunks if path == "/world/robot/camera/depth") >= 1
    assert counts["/world/robot"] >= 1
    # Every subsystem of the loop shows up with its archetype.
    expect = {
        "/world/trajectory/truth/0": "LineStrips3D:strips",
        "/world/trajectory/estimate/0": "LineStrips3D:strips",
        "/world/estimate": "Transform3D:translation",
        "/world/particles/first_stage": "Arrows3D:vectors",
        "/world/particles/refined": "Arrows3D:colors",
        "/world/robot/fspf/plane_points": "Points3D:positions",
        "/world/robot/fspf/normals": "Arrows3D:vectors",
        "/world/localization/scene_lines": "LineStrips3D:strips",
        "/world/robot/avoidance/fan": "LineStrips3D:strips",
        "/world/robot/avoidance/chosen": "Arrows3D:vectors",
        "/world/robot/avoidance/near_field": "LineStrips3D:strips",
        "/world/people": "Boxes3D:centers",
    }
    for path, column in expect.items():
        assert any(column in c for p_, c in chunks if p_ == path), path


def test_trajectory_strips_are_bounded(tmp_path: Path) -> None:
    """A long path is logged as a chain of strips of at most TRAIL_CHUNK points each."""
    import numpy as np

    from sim.viz.recording import TRAIL_CHUNK, Recorder

    rec = Recorder(tmp_path / "t.rrd", every=50)
    n = 3 * TRAIL_CHUNK + 10
    for f in range(n):
        rec.set_time(f, f / 30)
        rec.log_pose(f, np.array([0.01 * f, 0.0, 0.0]))
    assert rec._truth.chunk == 3 and len(rec._truth.points) <= TRAIL_CHUNK
    rec.reset_trajectory()
    assert rec._truth.chunk == 0 and not rec._truth.points
    rec.close()


def test_an_unwritable_recording_path_is_a_one_line_input_error(tmp_path: Path) -> None:
    from autonomy.common.errors import InputError
    from sim.viz.recording import Recorder

    with pytest.raises(InputError, match="expected a file name for the rerun recording, got a directory"):
        Recorder(tmp_path)
    (tmp_path / "f").write_text("")
    with pytest.raises(InputError, match="cannot write the rerun recording"):
        Recorder(tmp_path / "f" / "run.rrd")  # a file where a directory should be


def test_the_trajectory_figure_marks_start_end_and_each_waypoints_outcome() -> None:
    from types import SimpleNamespace

    from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
    from sim.experiments.report import waypoint_markers

    g = NavGraph(nodes=tuple(NavNode(i, float(i), 0.0) for i in range(5)), edges=tuple(NavEdge(i, i + 1) for i in range(4)))
    mission = SimpleNamespace(
        waypoints=[1, 2, 3, 4], current=2,
        events=[{"waypoint": 1, "status": "reached"}, {"waypoint": 2, "status": "timeout"}],
    )
    truth = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.0], [2.0, 1.0, 0.0]])
    m = waypoint_markers(SimpleNamespace(mission=mission), g, truth)
    np.testing.assert_allclose(m["start"], [[0.0, 0.0]])
    np.testing.assert_allclose(m["end"], [[2.0, 1.0]])
    np.testing.assert_allclose(m["waypoints reached"], [[1.0, 0.0]])
    np.testing.assert_allclose(m["waypoints missed"], [[2.0, 0.0]])
    np.testing.assert_allclose(m["waypoints not visited"], [[3.0, 0.0], [4.0, 0.0]])
