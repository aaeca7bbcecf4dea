"""The real-floors benchmark: maps x seeds as sweep trials, one table with a total row."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from autonomy.common.errors import InputError
from sim.experiments import real_floors as rf
from sim.experiments.kinds import load_experiment
from tests.helpers import GL, err_line

ROOT = Path(__file__).resolve().parents[2]
MAPS = ROOT / "sim" / "assets" / "maps"


def scenario(tmp_path: Path, bench: str = "", extra: str = "") -> Path:
    """A real-floors scenario on the shipped GHC4 floor (its graph shipped beside it)."""
    bench = bench or f'maps_dir = "{MAPS}"\nmaps = ["GHC4"]\nseeds = [5, 6]\n'
    p = tmp_path / "floors.toml"
    p.write_text(
        'kind = "real_floors"\nname = "floors"\n[benchmark]\n' + bench
        + "[actors]\nrandom_people = 2\nrandom_furniture = 2\n"
        + '[mission]\nfollower = "navigator"\ntarget_distance_m = 3.0\nmax_duration_s = 8.0\n' + extra,
        encoding="utf-8",
    )
    return p


def result(name: str, seed: int, **m) -> dict:
    """A trial's result as :func:`sim.experiments.real_floors.trial` returns it."""
    metrics = {
        "distance_m": 100.0, "duration_s": 200.0, "wall_time_s": 100.0, "frames": 6000, "collisions": 1,
        "collision_incidents": 1, "resets": 0, "truth_resets_needed": 0, "lost_alarms": 1, "lost_false_alarms": 0,
        "waypoints_reached": 4, "loc_error_mean_m": 0.05, "loc_error_p95_m": 0.1, "loc_error_max_m": 0.3,
        "realtime_factor": 2.0, "blind_share": 0.2, "blind_stretch_max_m": 6.0,
    }
    metrics.update(m)
    res = {"rss_start_mb": 500.0, "rss_end_mb": 510.0, "frame_ms_start": 20.0, "frame_ms_end": 21.0}
    return {"map": name, "seed": seed, "graph": "walls", "metrics": metrics, "resources": res, "waypoint_timeouts": 1, "waypoint_wrong_place": 0}


def test_rows_and_total_as_computed_by_hand() -> None:
    a = result("A", 1)
    b = result("B", 1, distance_m=300.0, duration_s=600.0, wall_time_s=400.0, frames=18000, collisions=3, resets=2,
               truth_resets_needed=1, lost_alarms=3, lost_false_alarms=2, loc_error_mean_m=0.09, loc_error_p95_m=0.4,
               loc_error_max_m=1.5, realtime_factor=1.5, blind_share=0.6, blind_stretch_max_m=25.5)
    b["resources"] = {"rss_start_mb": 480.0, "rss_end_mb": 530.0, "frame_ms_start": 25.0, "frame_ms_end": 19.0}
    b["waypoint_timeouts"] = 2
    rows = [rf.table_row(a), rf.table_row(b)]
    assert (rows[1]["contacts"], rows[1]["resets"], rows[1]["truth_resets"], rows[1]["false_alarms"]) == (3, 2, 1, 2)
    assert (rows[1]["error_mean_cm"], rows[1]["error_p95_cm"], rows[1]["error_max_cm"]) == (9.0, 40.0, 150.0)
    assert (rows[1]["blind_pct"], rows[1]["blind_stretch_max_m"]) == (60.0, 25.5)
    t = rf.total_row(rows)
    assert t["runs"] == 2 and t["distance_m"] == 400.0 and t["contacts"] == 4 and t["resets"] == 2
    assert t["truth_resets"] == 1 and t["lost_alarms"] == 4 and t["false_alarms"] == 2 and t["waypoint_timeouts"] == 3
    # Error mean weighted by frames: (5 cm x 6000 + 9 cm x 18000) / 24000 = 8 cm.
    assert t["error_mean_cm"] == 8.0
    assert (t["error_p95_cm"], t["error_max_cm"], t["blind_stretch_max_m"]) == (40.0, 150.0, 25.5)  # the worst run's
    assert t["blind_pct"] == 50.0  # weighted by distance: (20 % x 100 m + 60 % x 300 m) / 400 m
    assert t["realtime_factor"] == 800.0 / 500.0  # all simulated time over all wall time
    assert (t["rss_start_mb"], t["rss_end_mb"], t["frame_ms_start"], t["frame_ms_end"]) == (500.0, 530.0, 25.0, 21.0)
    assert t["resets_per_km"] == 5.0  # 2 resets in 0.4 km
    md = rf.markdown_table(rows, t).splitlines()
    assert len(md) == 2 + 3
    assert md[0].startswith("| map | seed | distance m | contacts | resets |")
    assert md[3].split("|")[1:6] == [" B ", " 1 ", " 300.0 ", " 3 ", " 2 "]
    assert md[4].startswith("| **total** (2 runs) |  | 400.0 | 4 | 2 | 1 | 4 | 2 | 3 | 8.0 | 40.0 | 150.0 | 50 | 25.5 | 1.60 |")


def test_a_run_without_a_figure_shows_a_dash_and_the_total_skips_it() -> None:
    a = result("A", 1)
    for k in ("resets", "truth_resets_needed", "lost_alarms", "lost_false_alarms", "loc_error_mean_m", "loc_error_p95_m", "loc_error_max_m"):
        del a["metrics"][k]
    a["resources"] = {}
    b = result("B", 2)
    t = rf.total_row([rf.table_row(a), rf.table_row(b)])
    assert t["resets"] == 0 and t["lost_alarms"] == 1 and t["error_mean_cm"] == 5.0 and t["rss_end_mb"] == 510.0
    only_a = rf.total_row([rf.table_row(a)])
    assert only_a["resets"] is None and only_a["error_mean_cm"] is None and only_a["resets_per_km"] is None
    row = rf.markdown_table([rf.table_row(a)], only_a).splitlines()[2]
    assert row.split("|")[5].strip() == "–"


def test_maps_resolve_by_name_or_path_and_use_the_graph_beside(tmp_path: Path) -> None:
    exp, cfg = load_experiment(scenario(tmp_path))
    assert exp.kind == "real_floors" and cfg.replays == 2
    assert cfg.map_paths() == [("GHC4", MAPS / "GHC4.vectormap.txt")]
    assert rf.map_scenario(cfg, 0).map.navgraph == str(MAPS / "GHC4.navigation.json")
    _, walls = load_experiment(scenario(tmp_path), ["benchmark.graphs=walls", f'benchmark.maps=["{MAPS / "GHC4.vectormap.txt"}"]'])
    assert rf.map_scenario(walls, 0).map.navgraph == ""
    specs = rf.trials(cfg, 1, cfg.seed)
    assert specs == [{"id": "00-GHC4-seed5", "map_index": 0, "map": "GHC4", "seed": 5}]
    with pytest.raises(InputError, match="--trials 3"):
        rf.trials(cfg, 3, cfg.seed)
    with pytest.raises(InputError, match="--seed 9"):
        rf.trials(cfg, 2, 9)


@pytest.mark.parametrize(
    ("bench", "extra", "says"),
    [
        (f'maps_dir = "{MAPS}"\nmaps = ["GHC4", "NOPE"]\nseeds = [1]\n', "", "NOPE.vectormap.txt"),
        (f'maps_dir = "{MAPS}"\nmaps = ["GHC4"]\nseeds = []\n', "", "benchmark.seeds"),
        (f'maps_dir = "{MAPS}"\nmaps = []\nseeds = [1]\n', "", "benchmark.maps"),
        (f'maps_dir = "{MAPS}"\nmaps = ["GHC4"]\nseeds = [1, 1]\n', "", "each seed once"),
        (f'maps_dir = "{MAPS}"\nmaps = ["GHC4"]\nseeds = [1]\ngraphs = "hand"\n', "", "benchmark.graphs"),
        (f'maps_dir = "{MAPS}"\nmaps = ["GHC4"]\nseeds = [1]\n', '[map]\nname = "small_floor"\n', "remove [map]"),
    ],
)
def test_bad_input_is_a_one_line_error(tmp_path: Path, capsys, bench: str, extra: str, says: str) -> None:
    from sim.cli import main

    assert main(["sweep", str(scenario(tmp_path, bench, extra)), "--out", str(tmp_path / "o")]) == 2
    line = err_line(capsys)
    assert says in line and "floors.toml" in line


def test_a_scenario_without_benchmark_is_a_one_line_error(tmp_path: Path) -> None:
    p = tmp_path / "f.toml"
    p.write_text('kind = "real_floors"\nname = "f"\n', encoding="utf-8")
    with pytest.raises(InputError, match=r"f\.toml: benchmark\.maps: list at least one"):
        load_experiment(p)


def test_shipped_scenario_parses_and_shortens() -> None:
    maps = ROOT.parent / "shared" / "maps"
    if not (maps / "GHC5.vectormap.txt").is_file():
        pytest.skip("the real floors beside the repository are not here")
    _, cfg = load_experiment(ROOT / "scenarios" / "real_floors.toml", ["mission.target_distance_m=50"])
    assert cfg.mission.target_distance_m == 50.0 and len(cfg.map_paths()) == 11


@pytest.mark.slow
@pytest.mark.skipif(not GL, reason="needs an OpenGL context (MUJOCO_GL=egl) to render depth")
def test_sweep_on_the_shipped_floor_prints_one_table_and_resumes(tmp_path: Path, capsys) -> None:
    from sim.cli import main

    scn, out = scenario(tmp_path), tmp_path / "out"
    assert main(["sweep", str(scn), "--out", str(out), "--workers", "1"]) == 0
    printed = capsys.readouterr().out
    assert printed.count("| **total** (2 runs) |") == 1 and "| GHC4 | 5 |" in printed and "| GHC4 | 6 |" in printed
    table = json.loads((out / "table.json").read_text())
    assert [(r["map"], r["seed"]) for r in table["rows"]] == [("GHC4", 5), ("GHC4", 6)]
    assert all(r["graph"] == "file" and r["distance_m"] > 0 and r["frame_ms_start"] > 0 for r in table["rows"])
    assert (out / "table.md").read_text() in printed
    report = json.loads((out / "report.json").read_text())
    assert report["kind"] == "real_floors" and report["metrics"]["runs"] == 2
    # Resumed, the finished runs are kept and none is run again.
    assert main(["sweep", str(scn), "--out", str(out), "--workers", "1", "--resume"]) == 0
    assert json.loads((out / "report.json").read_text())["sweep"]["run_now"] == 0


def test_the_shipped_real_floor_loads_with_its_graph_and_its_attribution() -> None:
    from sim.experiments.site import load_building
    from sim.scenario import load_scenario

    scn = load_scenario(ROOT / "scenarios" / "ghc4.toml")
    b = load_building(scn)
    assert b.vectormap.n_segments > 2000 and b.navgraph.n_nodes > 500
    x0, y0, x1, y1 = b.vectormap.extent()
    xy = b.navgraph.node_xy()
    assert ((xy[:, 0] > x0) & (xy[:, 0] < x1) & (xy[:, 1] > y0) & (xy[:, 1] < y1)).all()
    note = (MAPS / "README.md").read_text(encoding="utf-8")
    assert "ut-amrl/amrl_maps" in note and "38db3f2b17f7313aa91ea1315fe4834d1a25b3df" in note and "BSD" in note
