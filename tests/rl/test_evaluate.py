"""The evaluation: metrics against closed forms, missions shared by policies, the loop, the CLI."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import sim  # noqa: F401  (registers DepthNav-v0)
from autonomy.common.errors import InputError
from sim.cli import main
from sim.rl.evaluate import (
    EpisodeResult,
    compare,
    episode_env_kwargs,
    evaluate,
    mean_ci95,
    path_length,
    run_episode,
    soft_spl,
    spl,
    summarize,
)
from sim.rl.policies import ClassicalPolicy, RandomPolicy
from sim.rl.policy_specs import make_policy
from sim.rl.splits import BENCHMARK_TASK, LEARNER_OBS, episode_specs
from tests.helpers import GL, err_line

needs_gl = pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")


# -- metrics ---------------------------------------------------------------------------
def test_spl_closed_form() -> None:
    assert spl(True, 5.0, 5.0) == 1.0
    assert spl(True, 5.0, 10.0) == 0.5
    assert spl(True, 6.0, 8.0) == 0.75
    assert spl(True, 5.0, 4.5) == 1.0  # stopped within the success radius: p < l
    assert spl(False, 5.0, 5.0) == 0.0


def test_soft_spl_closed_form() -> None:
    # halfway there along a path of twice the geodesic: 0.5 * 10 / 20
    assert soft_spl(5.0, 10.0, 20.0) == pytest.approx(0.25)
    assert soft_spl(0.0, 10.0, 10.0) == 1.0
    assert soft_spl(12.0, 10.0, 3.0) == 0.0  # farther than at the start
    assert soft_spl(10.0, 10.0, 0.0) == 0.0  # did not move
    assert soft_spl(0.4, 8.0, 7.6) == pytest.approx(0.95)  # 1 - 0.4 / 8, p < l


def test_path_length_and_ci() -> None:
    assert path_length(np.array([[0, 0], [3, 4], [3, 10]])) == pytest.approx(11.0)
    assert path_length(np.zeros((1, 2))) == 0.0
    m, h = mean_ci95([0, 1, 0, 1])
    assert m == 0.5 and h == pytest.approx(1.959964 * math.sqrt(1 / 3) / 2, rel=1e-6)
    m, h = mean_ci95([2.0])
    assert m == 2.0 and math.isnan(h)


def _result(i: int, success: bool, spl_: float, collisions: int, steps: int) -> EpisodeResult:
    return EpisodeResult(i, 1, 2, success, spl_, spl_, 5.0, 6.0, 0.3, collisions, steps, 0.05, 0, 1.0)


def test_summary() -> None:
    rs = [_result(0, True, 0.8, 0, 100), _result(1, False, 0.0, 2, 300), _result(2, True, 1.0, 1, 200)]
    s = summarize(rs, wall_s=4.0)
    assert s["episodes"] == 3 and s["total_steps"] == 600 and s["steps_per_s"] == 150.0
    assert s["success"] == pytest.approx(2 / 3) and s["spl"] == pytest.approx(0.6)
    assert s["collisions"] == 1.0 and s["collisions_ci95"] == pytest.approx(1.959964 / math.sqrt(3), rel=1e-6)
    assert s["loc_error_m"] == pytest.approx(0.05) and s["path_length_m"] == 6.0


# -- policies ----------------------------------------------------------------------------
def test_make_policy() -> None:
    assert isinstance(make_policy("random"), RandomPolicy) and make_policy("random:3").seed == 3
    assert isinstance(make_policy("classical"), ClassicalPolicy)
    assert make_policy("classical").env_kwargs() == {"stack_policy": True}
    for bad in ("greedy", "classical:1", "random:x", "ppo:", "ppo:/no/such/model", "bc:", "bc:/no/such/model"):
        with pytest.raises(InputError, match="policy"):
            make_policy(bad)


def test_random_policy_is_per_episode() -> None:
    p = RandomPolicy(1)
    p.reset(7)
    a = [p.act({}, {}) for _ in range(3)]
    p.reset(8)
    p.act({}, {})
    p.reset(7)
    b = [p.act({}, {}) for _ in range(3)]
    np.testing.assert_array_equal(a, b)
    assert np.all(np.abs(a) <= 1.0)


class _Fixed:
    """A scripted policy: the same action every step; observation settings of a learner."""

    name = "fixed"

    def __init__(self, action, env: dict | None = None) -> None:
        self.action = np.asarray(action, dtype=np.float64)
        self.env = env or {}
        self.resets: list[int] = []

    def env_kwargs(self) -> dict:
        return dict(self.env)

    def reset(self, seed: int) -> None:
        self.resets.append(seed)

    def act(self, obs, info) -> np.ndarray:
        return self.action


def test_policy_task_keys_are_dropped_with_a_warning() -> None:
    p = _Fixed([0, 0, 0], dict(LEARNER_OBS, max_steps=7, building_seeds=(1000, 1001), min_goal_distance_m=3.0))
    with pytest.warns(UserWarning, match="max_steps=7 ignored"):
        kw = episode_env_kwargs(p, 2001, {"n_people": 0})
    assert kw["max_steps"] == BENCHMARK_TASK["max_steps"] and kw["building_seeds"] == (2001,)
    assert kw["depth_shape"] == (60, 80) and kw["n_people"] == 0


# -- the loop ------------------------------------------------------------------------------
@needs_gl
def test_same_missions_for_every_policy() -> None:
    """An episode spec fixes the start, goal, furniture and people whatever the policy's env
    arguments (the stack as a policy, a learner's observations)."""
    policies = [RandomPolicy(), ClassicalPolicy(), _Fixed([0, 0, 0], dict(LEARNER_OBS))]
    specs = episode_specs("val", 6, seed=1)[::2]  # buildings 2000 and 2002
    seen: dict[int, list] = {s.index: [] for s in specs}
    for p in policies:
        for s in specs:
            env = gym.make("DepthNav-v0", **episode_env_kwargs(p, s.building_seed))
            try:
                _, info = env.reset(seed=s.reset_seed)
                site = env.unwrapped.site
                seen[s.index].append(
                    (info["pose"], info["goal"], info["goal_distance_m"], [(f.x, f.y, f.yaw) for f in site.furniture],
                     site.world.people.positions()[:, :2].copy())
                )
                assert site.seed == s.building_seed
            finally:
                env.close()
    for runs in seen.values():
        ref = runs[0]
        assert 0.0 < ref[2] <= 12.0 + 1e-9  # the graph distance is 3-12 m; in sight, a straight line
        for other in runs[1:]:
            np.testing.assert_array_equal(other[0], ref[0])
            np.testing.assert_array_equal(other[1], ref[1])
            assert other[2] == ref[2] and other[3] == ref[3]
            np.testing.assert_array_equal(other[4], ref[4])
    # different specs are different missions
    assert not np.array_equal(seen[specs[0].index][0][0], seen[specs[1].index][0][0])


@needs_gl
def test_run_episode_path_and_on_step() -> None:
    """The path length is the trajectory the steps report; standing still scores 0."""
    spec = episode_specs("val", 1, seed=0)[0]
    kw = dict(max_steps=40, n_people=0)
    for action, moves in (([0.0, 0.0, 0.0], False), ([0.6, 0.0, 0.3], True)):
        p = _Fixed(action)
        env = gym.make("DepthNav-v0", **episode_env_kwargs(p, spec.building_seed, kw))
        poses, chosen_on, last = [], [], {}

        def on_step(obs, act, reward, next_obs, terminated, truncated, info, poses=poses, chosen_on=chosen_on, last=last, p=p):
            chosen_on.append(obs is last.get("obs", obs))
            last["obs"] = next_obs
            poses.append(info["pose"][:2].copy())
            np.testing.assert_array_equal(act, p.action)

        try:
            _, info0 = env.reset(seed=spec.reset_seed)
            r = run_episode(env, p, spec, on_step=on_step)
        finally:
            env.close()
        assert p.resets == [spec.reset_seed] and r.steps == 40 == len(poses) and all(chosen_on)
        assert r.start_pose == tuple(info0["pose"]) and r.geodesic_m == info0["goal_distance_m"]
        assert r.path_length_m == pytest.approx(path_length(np.vstack([info0["pose"][:2], *poses])), rel=1e-12)
        assert not r.success and r.spl == 0.0
        if moves:
            # 0.6 * 0.75 m/s for 40 frames, less the acceleration ramp
            assert 0.3 < r.path_length_m < 0.6 * 0.75 * 40 / 30 + 1e-6
        else:
            assert r.path_length_m < 1e-3
            assert r.final_distance_m == pytest.approx(r.geodesic_m, abs=1e-3)
            assert r.soft_spl == pytest.approx(0.0, abs=1e-3)


@needs_gl
def test_evaluate_random_and_classical(tmp_path: Path) -> None:
    out = tmp_path / "eval.json"
    kw = dict(max_steps=120)
    reports = compare(["random", "classical"], "val", episodes=2, seed=0, env_kwargs=kw, progress=False, out=out)
    assert [r.policy for r in reports] == ["random", "classical"]
    for r in reports:
        assert [x.index for x in r.results] == [0, 1] and [x.building_seed for x in r.results] == [2000, 2001]
        assert all(x.steps <= 120 for x in r.results)
        assert r.summary["episodes"] == 2 and r.summary["total_steps"] == sum(x.steps for x in r.results)
        assert r.env_kwargs["max_steps"] == 120 and not r.interrupted
    # the same missions; the stack gets closer to the goal than random actions
    assert [x.start_pose for x in reports[0].results] == [x.start_pose for x in reports[1].results]
    assert [x.goal_xy for x in reports[0].results] == [x.goal_xy for x in reports[1].results]
    assert reports[1].summary["soft_spl"] > reports[0].summary["soft_spl"]
    doc = json.loads(out.read_text())
    assert [d["policy"] for d in doc["reports"]] == ["random", "classical"] and "SPL" in doc["table"]
    assert doc["reports"][1]["results"][0]["path_length_m"] == pytest.approx(reports[1].results[0].path_length_m)
    # evaluate alone: its own report file
    single = tmp_path / "one.json"
    r = evaluate(ClassicalPolicy(), "val", episodes=1, env_kwargs=kw, progress=False, out=single)
    # the same episode again, bit for bit (but for the wall time)
    assert dataclasses.replace(r.results[0], wall_s=0.0) == dataclasses.replace(reports[1].results[0], wall_s=0.0)
    assert json.loads(single.read_text())["summary"]["episodes"] == 1


class _Interrupting(_Fixed):
    def reset(self, seed: int) -> None:
        super().reset(seed)
        if len(self.resets) == 3:
            raise KeyboardInterrupt


@needs_gl
def test_interrupted_evaluation_writes_what_finished(tmp_path: Path) -> None:
    out = tmp_path / "eval.json"
    with pytest.raises(KeyboardInterrupt):
        evaluate(_Interrupting([0, 0, 0]), "val", episodes=4, env_kwargs=dict(max_steps=5), progress=False, out=out)
    doc = json.loads(out.read_text())
    assert doc["interrupted"] is True and [r["index"] for r in doc["results"]] == [0, 1]
    assert doc["summary"]["episodes"] == 2 and doc["episodes"] == 4


# -- the CLI -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv, pattern",
    [
        (["--policy", "random", "--split", "dev"], "split 'dev' unknown"),
        (["--policy", "greedy"], "policy 'greedy' unknown"),
        (["--policy", "random", "ppo:/no/such/dir"], "/no/such/dir not found"),
        (["--policy", "random", "--episodes", "0"], "--episodes"),
        (["--policy", "random", "--seed", "-1"], "--seed"),
        (["--split", "val"], "--policy"),
        (["--policy", "random", "--task", "DepthNav-v9"], "--task DepthNav-v9"),
    ],
)
def test_eval_cli_errors(capsys, argv, pattern) -> None:
    assert main(["eval", *argv]) == 2
    assert pattern in err_line(capsys)


def test_output_errors_come_before_any_episode(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    for out, words in ((tmp_path, "is a directory"), (tmp_path / "file" / "r.json", "cannot make the directory")):
        with pytest.raises(InputError, match=words):
            evaluate("random", "val", episodes=1, out=out, progress=False)
        with pytest.raises(InputError, match=words):
            compare(["random"], "val", episodes=1, out=out, progress=False)


@needs_gl
def test_eval_cli_table(tmp_path: Path, capsys, monkeypatch) -> None:
    monkeypatch.setattr("sim.rl.splits.BENCHMARK_TASK", {**BENCHMARK_TASK, "max_steps": 30})
    out = tmp_path / "b.json"
    assert main(["eval", "--policy", "random", "classical", "--episodes", "1", "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "| policy" in text and "| random" in text and "| classical" in text and f"wrote {out}" in text
    assert len(json.loads(out.read_text())["reports"]) == 2


@needs_gl
def test_a_decision_level_task_is_evaluated_on_the_same_frozen_episodes() -> None:
    """The same val episode on DepthNav-v0 and DepthNavLocal-v0: the same start and goal
    (checked against the frozen file), the task's own observations and step limit."""
    from sim.rl.splits import benchmark_task

    assert benchmark_task("DepthNavLocal-v0")["max_steps"] == 200 and benchmark_task()["max_steps"] == 1000
    v0 = evaluate("random", "val", episodes=1, env_kwargs={"max_steps": 4}, progress=False)
    local = evaluate("random", "val", episodes=1, env_kwargs={"max_steps": 4}, progress=False, task="DepthNavLocal-v0")
    assert v0.task == "DepthNav-v0" and local.task == "DepthNavLocal-v0" and local.to_dict()["task"] == "DepthNavLocal-v0"
    assert local.frozen_episodes == v0.frozen_episodes == 1
    assert local.results[0].geodesic_m == v0.results[0].geodesic_m
    assert local.env_kwargs["max_steps"] == 4
