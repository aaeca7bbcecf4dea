"""The frozen benchmark episodes: the file against the code, the check at every reset, the
one-line errors, and the generator."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from sim.cli import main
from sim.rl.benchmark_episodes import (
    EPISODES_DIR,
    FIELDS,
    FROZEN_EPISODES,
    FROZEN_SEED,
    FROZEN_SPLITS,
    FrozenEpisode,
    FrozenEpisodeError,
    UnfrozenEpisodesWarning,
    benchmark_specs,
    episodes_file,
    first_difference,
    load_frozen_episodes,
    shown_path,
)
from sim.rl.evaluate import evaluate
from sim.rl.freeze_episodes import main as freeze_main
from sim.rl.freeze_episodes import produce, to_text
from sim.rl.splits import BENCHMARK_TASK, SPLITS, episode_specs
from tests.helpers import GL, err_line

needs_gl = pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")

ROOT = Path(__file__).resolve().parents[2]
FILE = episodes_file()


def _doc() -> dict:
    return json.loads(FILE.read_text(encoding="utf-8"))


def _tampered(tmp_path: Path, edit) -> Path:
    """A copy of the committed file with ``edit(doc)`` applied."""
    doc = _doc()
    edit(doc)
    out = tmp_path / "DepthNav-v0.json"
    out.write_text(to_text(doc), encoding="utf-8")
    return out


class _Still:
    """Stands still; asks for no env arguments."""

    name = "still"

    def env_kwargs(self) -> dict:
        return {}

    def reset(self, seed: int) -> None:
        pass

    def act(self, obs, info) -> np.ndarray:
        return np.zeros(3)


# -- the file against the code --------------------------------------------------------------
def test_the_file_covers_exactly_the_episode_specs() -> None:
    """Val and test, seed 0: the file's episodes are episode_specs' (count, order,
    buildings, reset seeds), on the code's task and splits."""
    assert FILE == ROOT / "sim" / "rl" / "episodes" / "DepthNav-v0.json" and FILE.parent == EPISODES_DIR
    assert shown_path(FILE) == "sim/rl/episodes/DepthNav-v0.json"
    assert FILE.stat().st_size < 120_000
    doc = _doc()
    assert doc["task_id"] == "DepthNav-v0" and doc["seed"] == FROZEN_SEED == 0
    assert doc["task"] == {k: v for k, v in BENCHMARK_TASK.items()} and doc["fields"] == FIELDS
    assert sorted(doc["splits"]) == sorted(FROZEN_SPLITS) == ["test", "val"]
    for name in FROZEN_SPLITS:
        eps = doc["splits"][name]["episodes"]
        specs = episode_specs(name, FROZEN_EPISODES, FROZEN_SEED)
        assert len(eps) == len(specs) == FROZEN_EPISODES == 100
        assert [(e["index"], e["building_seed"], e["reset_seed"]) for e in eps] == [
            (s.index, s.building_seed, s.reset_seed) for s in specs
        ]
        assert doc["splits"][name]["building_seeds"] == list(SPLITS[name].building_seeds)
        for e in eps:
            assert set(e) == set(FIELDS) and len(e["start"]) == 3 and len(e["goal"]) == 2
            assert 0.0 < e["goal_distance_m"] <= BENCHMARK_TASK["max_goal_distance_m"] + 1e-6
            assert len(e["furniture"]) == BENCHMARK_TASK["n_furniture"] and len(e["people"]) == BENCHMARK_TASK["n_people"]
    loaded = load_frozen_episodes()
    assert {k: len(v) for k, v in loaded.episodes.items()} == {"val": 100, "test": 100}


def test_the_file_is_package_data() -> None:
    """An installed package finds it beside sim/rl (pyproject's package-data)."""
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    patterns = cfg["tool"]["setuptools"]["package-data"]["sim"]
    assert any(FILE.relative_to(ROOT / "sim").match(p) for p in patterns)


@needs_gl
def test_the_current_code_produces_the_frozen_episodes() -> None:
    """The first episodes of each split (each building once) regenerated from the code
    are the file's, number for number (to 1e-6, as written)."""
    doc = _doc()
    for name in FROZEN_SPLITS:
        specs = episode_specs(name, 5, FROZEN_SEED)
        for rec in produce(specs):
            frozen = doc["splits"][name]["episodes"][rec["index"]]
            assert first_difference(frozen, rec) is None
            assert rec == frozen


# -- which episodes an evaluation runs -------------------------------------------------------
def test_benchmark_specs_read_the_file() -> None:
    specs = benchmark_specs("val", 3)
    assert all(isinstance(s, FrozenEpisode) for s in specs) and [s.index for s in specs] == [0, 1, 2]
    assert [(s.building_seed, s.reset_seed) for s in specs] == [(s.building_seed, s.reset_seed) for s in episode_specs("val", 3)]
    assert specs[0].source == "sim/rl/episodes/DepthNav-v0.json" and specs[0].split == "val"
    assert all(isinstance(s, FrozenEpisode) for s in benchmark_specs("test", 100))
    # the train split is not frozen: the specs as before, without a word
    assert benchmark_specs("train", 2) == episode_specs("train", 2)


def test_episodes_beyond_the_file_are_drawn_with_a_warning() -> None:
    with pytest.warns(UnfrozenEpisodesWarning, match=r"val episodes 100-101 of seed 0: not frozen \(sim/rl/episodes/DepthNav-v0.json holds episodes 0-99 of seed 0\)"):
        specs = benchmark_specs("val", 102)
    assert all(isinstance(s, FrozenEpisode) for s in specs[:100])
    assert specs[100:] == episode_specs("val", 102)[100:]
    with pytest.warns(UnfrozenEpisodesWarning, match="test episode 0 of seed 3: not frozen"):
        assert benchmark_specs("test", 1, seed=3) == episode_specs("test", 1, seed=3)


def test_first_difference_names_what_differs() -> None:
    rec = _doc()["splits"]["val"]["episodes"][7]

    def changed(key, i, delta):
        other = json.loads(json.dumps(rec))
        if isinstance(i, tuple):
            other[key][i[0]][i[1]] += delta
        elif i is None:
            other[key] += delta
        else:
            other[key][i] += delta
        return other

    assert first_difference(rec, rec) is None
    assert first_difference(rec, changed("start", 0, 5e-7)) is None  # within the tolerance
    assert first_difference(rec, changed("start", 2, 2 * math.pi)) is None  # the same heading
    assert first_difference(rec, changed("start", 2, 2e-6)).startswith("the env's start (x, y, yaw) (")
    assert "differs from the frozen one" in first_difference(rec, changed("start", 2, 2e-6))
    assert first_difference(rec, changed("goal", 1, -0.01)).startswith("the env's goal (x, y)")
    assert first_difference(rec, changed("goal_node", None, 1)).startswith("the env's goal node")
    assert "geodesic distance" in first_difference(rec, changed("goal_distance_m", None, 0.1))
    assert first_difference(rec, changed("furniture", (1, 1), 0.2)).startswith("the env's furniture piece 1 (")
    assert first_difference(rec, changed("people", (0, 6), 1.0)).startswith("the env's person 0 (")
    assert first_difference(rec, changed("reset_seed", None, 1)).startswith("the env's reset seed")


# -- the file's own errors -------------------------------------------------------------------
@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda d: d["task"].update(max_steps=500), r"the code's benchmark task differs from the frozen one \(max_steps\)"),
        (lambda d: d["splits"]["val"].update(building_seeds=[2000, 2001]), "the code's val split"),
        (lambda d: d.update(version=9), "version 9 unknown"),
        (lambda d: d.update(format="other"), "not a frozen-episodes file"),
        (lambda d: d["splits"]["test"]["episodes"][3].update(index=4), "test episode 3: expected a record with index 3"),
        (lambda d: d["splits"]["val"]["episodes"][2].update(building_seed=1000), "val episode 2: building 1000"),
    ],
)
def test_a_bad_file_is_a_one_line_error(tmp_path: Path, edit, words) -> None:
    bad = _tampered(tmp_path, edit)
    with pytest.raises(FrozenEpisodeError, match=words) as e:
        load_frozen_episodes(bad)
    assert str(e.value).startswith(f"{bad}: ") and "\n" not in str(e.value)


def test_a_missing_or_corrupt_file_is_a_one_line_error(tmp_path: Path) -> None:
    with pytest.raises(FrozenEpisodeError, match="frozen benchmark episodes not found"):
        load_frozen_episodes(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text("{", encoding="utf-8")
    with pytest.raises(FrozenEpisodeError, match="cannot read the frozen benchmark episodes"):
        benchmark_specs("val", 1, path=tmp_path / "bad.json")


# -- the check at every reset ----------------------------------------------------------------
def _move_start(doc: dict) -> None:
    doc["splits"]["val"]["episodes"][1]["start"][0] += 0.01


@needs_gl
def test_a_tampered_file_stops_the_evaluation(tmp_path: Path) -> None:
    """The env's reset no longer matches the file: a one-line error naming the file, the
    split, the episode and what differed, before any step of it."""
    bad = _tampered(tmp_path, _move_start)
    policy = _Still()
    with pytest.raises(FrozenEpisodeError) as e:
        evaluate(policy, "val", episodes=2, env_kwargs=dict(max_steps=3), progress=False, episodes_file=bad)
    msg = str(e.value)
    assert msg.startswith(f"{bad}: val episode 1: the env's start (x, y, yaw) (") and "\n" not in msg
    assert "differs from the frozen one (" in msg and msg.endswith("freeze a new version (docs/rl.md)")
    # the committed file: the same episodes pass, and the report says they were frozen
    r = evaluate(policy, "val", episodes=2, env_kwargs=dict(max_steps=3), progress=False)
    assert r.frozen_episodes == 2 and r.episodes_file == "sim/rl/episodes/DepthNav-v0.json"
    assert r.results[1].start_pose == pytest.approx(tuple(_doc()["splits"]["val"]["episodes"][1]["start"]), abs=1e-6)
    assert r.to_dict()["frozen_episodes"] == 2


@needs_gl
def test_eval_cli_on_a_tampered_file(tmp_path: Path, capsys, monkeypatch) -> None:
    _tampered(tmp_path, _move_start)
    monkeypatch.setattr("sim.rl.benchmark_episodes.EPISODES_DIR", tmp_path)
    monkeypatch.setattr("sim.rl.splits.BENCHMARK_TASK", {**BENCHMARK_TASK, "max_steps": 3})
    assert main(["eval", "--policy", "random", "--episodes", "2", "--no-progress"]) == 2
    line = err_line(capsys)
    assert line.startswith(f"depthnav: error: {tmp_path / 'DepthNav-v0.json'}: val episode 1: the env's start (x, y, yaw)")


@needs_gl
def test_eval_cli_notes_unfrozen_episodes(capsys, monkeypatch) -> None:
    monkeypatch.setattr("sim.rl.splits.BENCHMARK_TASK", {**BENCHMARK_TASK, "max_steps": 3})
    assert main(["eval", "--policy", "random", "--episodes", "1", "--seed", "5", "--no-progress"]) == 0
    out = capsys.readouterr()
    assert "depthnav: note: val episode 0 of seed 5: not frozen" in out.err and "frozen in" not in out.out
    assert main(["eval", "--policy", "random", "--episodes", "1", "--no-progress"]) == 0
    out = capsys.readouterr()
    assert "note" not in out.err and "1 of the 1 episodes frozen in sim/rl/episodes/DepthNav-v0.json" in out.out


# -- the generator ---------------------------------------------------------------------------
@needs_gl
def test_freeze_writes_checks_and_refuses_a_changed_benchmark(tmp_path: Path, capsys) -> None:
    out = tmp_path / "v.json"
    assert freeze_main(["--episodes", "2", "--out", str(out), "--no-progress"]) == 0
    doc, ref = json.loads(out.read_text()), _doc()
    for name in FROZEN_SPLITS:
        assert doc["splits"][name]["episodes"] == ref["splits"][name]["episodes"][:2]
    assert {k: v for k, v in doc.items() if k != "splits"} == {k: v for k, v in ref.items() if k != "splits"}
    assert freeze_main(["--check", "--out", str(out), "--no-progress"]) == 0
    capsys.readouterr()
    # a changed episode: --check fails and writing refuses, the file stays as it was
    doc["splits"]["test"]["episodes"][1]["goal"][0] += 1.0
    out.write_text(to_text(doc))
    before = out.read_text()
    for argv in (["--check"], []):
        assert freeze_main([*argv, "--out", str(out), "--no-progress"]) == 1
        line = err_line(capsys)
        assert f"{out}: test episode 1: the env's goal (x, y)" in line and "new version" in line
    assert out.read_text() == before
    # fewer episodes than the file holds would drop frozen ones
    assert freeze_main(["--episodes", "1", "--out", str(out), "--no-progress"]) == 2
    assert "would drop some" in err_line(capsys)


def test_freeze_into_a_missing_directory_is_one_line_before_any_work(tmp_path: Path, capsys, monkeypatch) -> None:
    import sim.rl.freeze_episodes as fe

    def no_work(*a, **k):
        raise AssertionError("episodes made for an --out that cannot be written")

    monkeypatch.setattr(fe, "freeze_document", no_work)
    out = tmp_path / "missing" / "x.json"
    assert freeze_main(["--episodes", "1", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("freeze_episodes: error: --out ") and "existing directory" in err[0]
