"""The committed reference policy (policies/DepthNavLocal-v0-ppo): it loads, says which
task it was trained on, and the evaluation reproduces its published episodes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.helpers import GL

pytest.importorskip("stable_baselines3")
pytestmark = pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")

POLICY = Path(__file__).resolve().parents[2] / "policies" / "DepthNavLocal-v0-ppo"


def test_the_committed_policy_reproduces_its_first_val_episodes() -> None:
    from sim.rl.evaluate import evaluate
    from sim.rl.sb3 import SB3Policy

    policy = SB3Policy.load(POLICY)
    assert policy.task == "DepthNavLocal-v0"
    published = json.loads((POLICY / "eval.json").read_text())["reports"][0]
    assert published["task"] == "DepthNavLocal-v0" and published["split"] == "val" and published["episodes"] == 50
    got = evaluate(policy, "val", episodes=3, seed=0, progress=False)
    assert got.task == "DepthNavLocal-v0"
    for mine, theirs in zip(got.results, published["results"][:3], strict=True):
        for key in ("success", "collisions", "steps"):
            assert getattr(mine, key) == theirs[key], key
        assert mine.path_length_m == pytest.approx(theirs["path_length_m"], abs=1e-6)


def test_the_committed_policy_on_another_task_is_one_line(capsys) -> None:
    from sim.cli import main

    assert main(["eval", "--policy", f"ppo:{POLICY}", "--task", "DepthNav-v0", "--episodes", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "trained on DepthNavLocal-v0" in err[0]


def test_a_policy_trained_through_the_safety_layer_is_evaluated_through_it(tmp_path, capsys) -> None:
    """How the action was carried out in training goes with the policy (its policy.json's
    env arguments); ``eval --safety-layer`` puts the layer under any policy, and a task
    without ``ranges`` refuses it in one line."""
    from sim.cli import main
    from sim.rl.sb3 import SB3Policy

    policy = SB3Policy.load(POLICY)
    assert "safety_layer" not in policy.env_kwargs()
    policy.meta["env_kwargs"]["safety_layer"] = True
    assert policy.env_kwargs()["safety_layer"] is True
    out = tmp_path / "r.json"
    assert main(["eval", "--policy", "random", "--task", "DepthNavLocal-v0", "--episodes", "1", "--safety-layer",
                 "--no-progress", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["reports"][0]["env_kwargs"]["safety_layer"] is True
    capsys.readouterr()
    assert main(["eval", "--policy", "random", "--episodes", "1", "--safety-layer", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "safety_layer" in err[0]
