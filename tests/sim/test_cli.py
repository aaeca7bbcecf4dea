"""The CLI contract: exit 0 on success, 2 with one stderr line (no traceback) on user error."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sim.cli import main
from sim.scenario import ASSETS_DIR
from tests.helpers import GL, err_line

SMALL = ASSETS_DIR / "small_floor.vectormap.txt"


def test_map_check_prints_summary(capsys) -> None:
    assert main(["map", "check", str(SMALL)]) == 0
    out = capsys.readouterr().out
    assert "segments" in out and "extent" in out and "total wall length" in out


@pytest.mark.parametrize(
    "content, pattern",
    [
        ("0, 0, 1\n", ":1:"),
        ("0, 0, 1, 1\n1, 2, x, 4\n", ":2:"),
        ("0, 0, nan, 1\n", ":1:"),
        ("", "no wall segments"),
    ],
)
def test_map_check_bad_file_exits_2(tmp_path: Path, capsys, content: str, pattern: str) -> None:
    p = tmp_path / "bad.vectormap.txt"
    p.write_text(content)
    assert main(["map", "check", str(p)]) == 2
    line = err_line(capsys)
    assert "bad.vectormap.txt" in line and pattern in line


def test_map_convert_round_trip(tmp_path: Path, capsys) -> None:
    from autonomy.maps.vectormap import load_vectormap

    j = tmp_path / "m.vectormap.json"
    t = tmp_path / "m.vectormap.txt"
    assert main(["map", "convert", str(SMALL), str(j)]) == 0
    assert main(["map", "convert", str(j), str(t)]) == 0
    np.testing.assert_array_equal(load_vectormap(SMALL).segments, load_vectormap(t).segments)


def test_map_render(tmp_path: Path) -> None:
    out = tmp_path / "m.png"
    graph = ASSETS_DIR / "small_floor.navigation.json"
    assert main(["map", "render", str(SMALL), "--graph", str(graph), "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_snapshot_writes_depth(tmp_path: Path) -> None:
    from autonomy.maps.navgraph import load_navgraph

    g = load_navgraph(ASSETS_DIR / "small_floor.navigation.json")
    x, y = g.node_xy()[0]
    backend = "gl" if GL else "raycast"
    rc = main(["snapshot", "small_floor", "--pose", f"{x},{y},0.0", "--no-noise", "--backend", backend, "--out", str(tmp_path)])
    assert rc == 0
    d = np.load(tmp_path / "depth.npy")
    assert d.shape == (480, 640) and d.dtype == np.float32 and np.isfinite(d).all()
    assert (d > 0).mean() > 0.5
    assert (tmp_path / "depth.png").stat().st_size > 1000


@pytest.mark.parametrize(
    "argv, pattern",
    [
        (["snapshot", "small_floor", "--pose", "1,2", "--out", "x"], "expected X,Y,THETA"),
        (["snapshot", "small_floor", "--pose", "1e6,2,0", "--out", "x"], "outside the map"),
        (["snapshot", "nowhere.txt", "--pose", "1,2,0", "--out", "x"], "map file not found"),
        (["run", "missing.toml"], "scenario file not found"),
        (["map", "check", "missing.vectormap.txt"], "not found"),
        (["map", "convert", str(SMALL), "out.svg"], "svg"),
        (["map"], "required"),
        (["frobnicate"], "invalid choice"),
        (["run"], "run: the following arguments are required: scenario"),
        (["run", "scenarios"], "scenarios: a directory; expected a scenario file (*.toml)"),
        (["run", "scenarios/demo.toml", "--seed", "-1"], "--seed: expected an integer >= 0, got -1"),
        (["run", "scenarios/demo.toml", "--set", "seed=-1"], "seed: expected an integer >= 0, got -1"),
        (["sweep", "scenarios/demo.toml", "--seed", "-1", "--out", "never"], "--seed: expected an integer >= 0"),
        (["reloc-sample", "--map", "small_floor", "--seed", "-5"], "--seed: expected an integer >= 0, got -5"),
    ],
)
def test_user_errors_exit_2_with_one_line(capsys, argv, pattern) -> None:
    assert main(argv) == 2
    assert pattern in err_line(capsys)


def test_unwritable_output_exits_2(tmp_path: Path, capsys) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    assert main(["map", "render", str(SMALL), "--out", str(blocker / "m.png")]) == 2
    assert "file" in err_line(capsys)


def test_run_with_bad_set_exits_2(capsys) -> None:
    assert main(["run", "scenarios/demo.toml", "--set", "robot.bogus=1"]) == 2
    assert "unknown key 'robot.bogus'" in err_line(capsys)


def test_scenarios_lists_each_file(capsys) -> None:
    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    assert "demo.toml" in out


def test_console_script_exit_code_and_no_traceback(tmp_path: Path) -> None:
    bad = tmp_path / "x.vectormap.txt"
    bad.write_text("1, 2, 3\n")
    r = subprocess.run([sys.executable, "-m", "sim.cli", "map", "check", str(bad)], capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    r = subprocess.run([sys.executable, "-m", "sim.cli", "scenarios"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    json.dumps(r.stdout)


@pytest.mark.parametrize(
    "argv",
    [
        ["eval", "--policy", "random", "--episodes", "1", "--out", "{dir}"],
        ["eval", "--policy", "random", "--episodes", "1", "--out", "{file}/r.json"],
        ["demos", "record", "--episodes", "1", "--out", "{file}/d.npz"],
        ["train", "ppo", "--steps", "10", "--out", "{file}/ppo"],
        ["reloc-sample", "--n", "1", "--out", "{dir}"],
        ["reloc-sample", "--n", "1", "--out", "{file}/r.json"],
    ],
)
def test_an_unusable_output_path_is_refused_before_any_episode(tmp_path: Path, capsys, argv) -> None:
    """A directory given as the output file, or a path under a file: one line naming
    --out, at once (an evaluation or a training run would otherwise end in a failed write)."""
    (tmp_path / "f").write_text("x")
    argv = [a.replace("{dir}", str(tmp_path)).replace("{file}", str(tmp_path / "f")) for a in argv]
    assert main(argv) == 2
    line = err_line(capsys)
    assert line.startswith("depthnav: error: --out ") and ("is a directory" in line or "cannot make the directory" in line)


@pytest.mark.parametrize(
    "argv",
    [["train", "ppo", "--steps", "10", "--out", "{tmp}/ppo"], ["eval", "--policy", "ppo:{tmp}", "--episodes", "1"]],
)
def test_without_pytorch_the_rl_commands_name_the_extra(tmp_path: Path, argv) -> None:
    """Where the rl extra is not installed (as after `make demo`), one line names it."""
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code = (
        "import sys; sys.modules['torch'] = None; sys.modules['stable_baselines3'] = None\n"
        f"from sim.cli import main; sys.exit(main({argv!r}))"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=Path(__file__).resolve().parents[2])
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and "needs torch" in lines[0] and "'.[rl]'" in lines[0], r.stderr


def test_version(capsys) -> None:
    from sim.cli import _version

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"depthnav {_version()}"
    assert _version().count(".") >= 1


def test_a_negative_seed_in_a_scenario_file_is_one_line(tmp_path: Path, capsys) -> None:
    f = tmp_path / "neg.toml"
    f.write_text('name = "neg"\nseed = -1\n')
    assert main(["run", str(f)]) == 2
    line = err_line(capsys)
    assert str(f) in line and "seed: expected an integer >= 0, got -1" in line


def test_argparse_errors_name_the_subcommand_once(capsys) -> None:
    assert main(["run"]) == 2
    line = err_line(capsys)
    assert line.startswith("depthnav: error: run: ") and "depthnav run" not in line


def test_a_shipped_scenario_is_found_by_name_from_anywhere(tmp_path: Path, monkeypatch) -> None:
    from sim.experiments.kinds import shipped_scenario
    from sim.scenario import SCENARIOS_DIR

    monkeypatch.chdir(tmp_path)
    assert shipped_scenario(Path("demo.toml")) == SCENARIOS_DIR / "demo.toml"
    assert shipped_scenario(Path("demo")) == SCENARIOS_DIR / "demo.toml"
    assert shipped_scenario(Path("nowhere.toml")) == Path("nowhere.toml")  # still "not found" later
    (tmp_path / "demo.toml").write_text('name = "mine"\n')
    assert shipped_scenario(Path("demo.toml")) == Path("demo.toml")  # a file here wins


def test_map_graph_with_a_robot_too_big_names_the_radius_not_an_internal_key(tmp_path: Path, capsys) -> None:
    assert main(["map", "graph", "small_floor", "--robot-radius", "5", "--out", str(tmp_path / "g.json")]) == 2
    line = err_line(capsys)
    assert "radius 5.00 m" in line and "padding_m" not in line


def test_map_render_takes_a_building_name(tmp_path: Path) -> None:
    assert main(["map", "render", "small_floor", "--out", str(tmp_path / "m.png")]) == 0
    assert (tmp_path / "m.png").stat().st_size > 1000


def test_a_mission_run_summary_is_three_short_lines() -> None:
    from sim.cli import run_summary

    m = {
        "distance_m": 302.4, "duration_s": 412.0, "realtime_factor": 5.6, "collisions": 0, "waypoints_reached": 8,
        "waypoints_failed": 0, "loc_error_mean_m": 0.021, "loc_error_p95_m": 0.047, "loc_error_max_m": 0.13, "resets": 0,
        "truth_resets_needed": 0, "lost_alarms": 1, "lost_false_alarms": 1, "relocalizations": 1, "recovered_by_robot": 0,
    }
    lines = run_summary("demo", m).splitlines()
    assert len(lines) == 3 and all(len(line) <= 100 for line in lines)
    assert lines[0] == "demo: 302 m in 412 s (5.6x real time); waypoints 8 reached, 0 failed; contacts 0"
    assert "2.1 / 4.7 / 13.0 cm" in lines[1] and "lost alarms 1 (false 1)" in lines[2]
    assert run_summary("cmp", {"fspf_failures": 0.05}) == "cmp: fspf_failures=0.05"


def test_snapshot_out_an_existing_file_is_one_line_before_rendering(tmp_path: Path, capsys) -> None:
    f = tmp_path / "fake.npz"
    f.write_text("")
    assert main(["snapshot", "small_floor", "--pose", "3,5.1,0", "--out", str(f)]) == 2
    assert f"--out {f}: is a file (expected a directory)" in err_line(capsys)


def test_a_map_error_names_the_file_given(tmp_path: Path, capsys) -> None:
    f = tmp_path / "one.vectormap.txt"
    f.write_text("0,0,1,0\n")
    assert main(["map", "check", str(f)]) == 2
    assert err_line(capsys).startswith(f"depthnav: error: {f}: ")


def test_snapshot_depth_png_has_a_colour_bar_and_a_clean_render_says_its_range(tmp_path: Path, capsys) -> None:
    from matplotlib.image import imread

    backend = "gl" if GL else "raycast"
    assert main(["snapshot", "corridor_loop", "--pose", "16.5,6.3,0", "--no-noise", "--backend", backend, "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "a clean render keeps depths beyond the sensor's 0.8-4 m" in out
    img = imread(str(tmp_path / "depth.png"))[..., :3]
    # A figure (title, colour bar, margins on white), not the bare 640 x 480 image.
    assert img.shape[:2] != (480, 640) and (img.min(axis=2) > 0.99).mean() > 0.1
    # The colour bar: a column right of the image running through the colour map, dark
    # blue at the bottom to dark red at the top.
    col = img[:, int(img.shape[1] * 0.9)]
    coloured = col[(col.max(axis=1) - col.min(axis=1)) > 0.3]
    assert len(coloured) > 100 and coloured[0][2] < coloured[0][0] and coloured[-1][2] > coloured[-1][0]


@pytest.mark.parametrize(("flag", "target", "pattern"), [("--out", "file", "is a file (expected a directory)"), ("--rrd", "dir", "is a directory (expected a file name)")])
def test_run_checks_where_it_writes_before_the_run(tmp_path: Path, capsys, monkeypatch, flag: str, target: str, pattern: str) -> None:
    import sim.experiments.runner as runner

    monkeypatch.setattr(runner, "build_run", lambda *a: pytest.fail("the run started"))
    (tmp_path / "file").write_text("x")
    (tmp_path / "dir").mkdir()
    argv = ["run", "demo", flag, str(tmp_path / target)] + (["--out", str(tmp_path / "o")] if flag == "--rrd" else [])
    assert main(argv) == 2
    assert err_line(capsys) == f"depthnav: error: {flag} {tmp_path / target}: {pattern}"


def test_sweep_out_an_existing_file_is_one_line(tmp_path: Path, capsys) -> None:
    (tmp_path / "file").write_text("x")
    assert main(["sweep", "demo", "--trials", "1", "--out", str(tmp_path / "file")]) == 2
    assert err_line(capsys) == f"depthnav: error: --out {tmp_path / 'file'}: is a file (expected a directory)"


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--env", "nonsense=1"], "--env 'nonsense=1': no env setting 'nonsense'"),
        (["--task", "DepthNav-v0", "--env", "clearance_reward=-0.1"], "--env: DepthNav: argument 'clearance_reward' expected 0 unless observe_ranges"),
    ],
)
def test_train_env_overrides_are_checked_before_training(tmp_path: Path, capsys, argv: list[str], needle: str) -> None:
    pytest.importorskip("stable_baselines3")
    base = ["train", "ppo", "--steps", "10", "--out", str(tmp_path / "ppo")]
    if "--task" not in argv:
        base += ["--task", "DepthNavLocal-v0"]
    assert main(base + argv) == 2
    assert needle in err_line(capsys)
    assert not (tmp_path / "ppo" / "model.zip").exists()
