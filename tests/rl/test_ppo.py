"""PPO training: a tiny run's files and learning curve against closed forms, the saved
policy loaded back, resume, Ctrl-C, configuration and CLI errors."""

from __future__ import annotations

import csv
import json
import re
from dataclasses import fields
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

import sim  # noqa: F401  (registers DepthNav-v0)
from autonomy.common.errors import InputError
from sim.cli import build_parser, main
from sim.rl.policies import Policy
from sim.rl.policy_specs import make_policy
from sim.rl.ppo import PPOTrainConfig, config_with, resume_config, train_ppo
from sim.rl.sb3 import SB3Policy
from sim.rl.splits import BENCHMARK_TASK, LEARNER_OBS, SPLITS, split_env_kwargs
from tests.helpers import GL, err_line

needs_gl = pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")

#: Episodes of MAX_STEPS steps: at most 0.75 m/s for 40 frames (1 m) never reaches a goal
#: at least 3 m away, so every episode is truncated at exactly MAX_STEPS.
MAX_STEPS = 40
N_ENVS, N_STEPS = 2, 64


def tiny(out: Path, total: int = 256, **changes) -> PPOTrainConfig:
    kw = dict(n_envs=N_ENVS, vec="dummy", n_steps=N_STEPS, batch_size=64, n_epochs=1, checkpoint_every=128, eval_episodes=0)
    cfg = PPOTrainConfig(out=str(out), total_steps=total, **{**kw, **changes})
    return config_with(cfg, max_steps=MAX_STEPS)


def rows(out: Path) -> list[dict[str, str]]:
    with (out / "progress.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def expected_episodes(steps: int) -> int:
    """Episodes finished after ``steps`` steps over N_ENVS envs of MAX_STEPS-step episodes."""
    return N_ENVS * ((steps // N_ENVS) // MAX_STEPS)


@needs_gl
@pytest.mark.slow
def test_train_load_act_resume(tmp_path: Path, monkeypatch) -> None:
    out = tmp_path / "ppo"
    res = train_ppo(tiny(out, eval_episodes=1, eval_env_kwargs={"max_steps": 10}))
    assert (res.steps, res.interrupted) == (256, False)
    for name in ("model.zip", "policy.json", "progress.csv", "curve.png", "eval.json", "vecnormalize.pkl"):
        assert (out / name).is_file(), name
    assert (out / "curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # One row per rollout of N_ENVS * N_STEPS steps; the episode counts and lengths follow.
    r = rows(out)
    assert [int(x["timesteps"]) for x in r] == [128, 256]
    assert [int(x["episodes"]) for x in r] == [expected_episodes(128), expected_episodes(256)] == [2, 6]
    assert all(float(x["ep_len_mean"]) == MAX_STEPS and float(x["success_rate"]) == 0.0 for x in r)
    assert 0 < float(r[0]["wall_s"]) < float(r[1]["wall_s"]) and float(r[1]["fps"]) > 0
    meta = json.loads((out / "policy.json").read_text())
    assert meta["steps"] == 256 and meta["episodes"] == 6 and meta["algorithm"] == "PPO"
    assert meta["env_kwargs"]["max_steps"] == MAX_STEPS and meta["config"]["n_steps"] == N_STEPS
    ev = json.loads((out / "eval.json").read_text())
    assert ev["summary"]["episodes"] == 1 and ev["split"] == "val"

    # The saved policy, through the evaluation's spec: the learner observations, acting
    # with the Gaussian's mean (computed here from the network, depth made channel-first).
    pol = make_policy(f"ppo:{out}")
    assert isinstance(pol, SB3Policy) and isinstance(pol, Policy)
    assert pol.env_kwargs() == dict(LEARNER_OBS)
    env = gym.make("DepthNav-v0", **split_env_kwargs("val", **pol.env_kwargs(), max_steps=5))
    obs, info = env.reset(seed=3)
    pol.reset(3)
    a = pol.act(obs, info)
    assert a.shape == (3,) and a.dtype == np.float32 and np.all(np.abs(a) <= 1.0)
    t = {k: torch.as_tensor(v[None]) for k, v in obs.items()}
    t["depth"] = t["depth"].permute(0, 3, 1, 2)
    with torch.no_grad():
        mean = pol.model.policy.get_distribution(t).distribution.mean.numpy()[0]
    np.testing.assert_allclose(a, np.clip(mean, -1, 1), rtol=1e-5, atol=1e-6)
    for _ in range(3):
        obs, *_, info = env.step(pol.act(obs, info))
    env.close()

    # Resume: the same configuration, more steps; the curve and the counts go on.
    with pytest.raises(InputError, match="holds a training run already"):
        train_ppo(tiny(out, total=512))
    with pytest.raises(InputError, match="n_epochs"):
        train_ppo(tiny(out, total=512, n_epochs=2), resume=True)
    res2 = train_ppo(resume_config(out, total_steps=512, eval_episodes=0), resume=True)
    assert (res2.steps, res2.session_steps) == (512, 256)
    r = rows(out)
    assert [int(x["timesteps"]) for x in r] == [128, 256, 384, 512]
    assert int(r[-1]["episodes"]) == 6 + expected_episodes(256)
    assert float(r[2]["wall_s"]) > float(r[1]["wall_s"])
    assert json.loads((out / "policy.json").read_text())["steps"] == 512
    assert res2.wall_s > res.wall_s

    # Ctrl-C during training: a checkpoint of the steps done, marked interrupted.
    calls = []

    def interrupt_second(path, row):
        calls.append(row["timesteps"])
        if len(calls) == 2:
            raise KeyboardInterrupt

    monkeypatch.setattr("sim.rl.ppo.append_progress", interrupt_second)
    res3 = train_ppo(tiny(tmp_path / "int", total=1024, checkpoint_every=10_000))
    assert res3.interrupted and res3.steps == 256 and res3.eval_summary is None
    meta = json.loads((tmp_path / "int" / "policy.json").read_text())
    assert meta["interrupted"] is True and meta["steps"] == 256


@pytest.mark.parametrize(
    "changes, name",
    [
        (dict(total_steps=0), "total_steps"),
        (dict(n_envs=0), "n_envs"),
        (dict(vec="fork"), "vec"),
        (dict(batch_size=4096), "batch_size"),
        (dict(learning_rate=-1.0), "learning_rate"),
        (dict(gamma=1.5), "gamma"),
        (dict(eval_episodes=-1), "eval_episodes"),
        (dict(seed=True), "seed"),
        (dict(normalize_reward="no"), "normalize_reward"),
        (dict(n_steps="64"), "n_steps"),
    ],
)
def test_config_errors(changes, name) -> None:
    with pytest.raises(InputError, match=f"'{name}'"):
        PPOTrainConfig(**changes)


def test_default_env_is_the_train_split_with_learner_observations() -> None:
    """Spelled out rather than through split_env_kwargs, the default factory's own call."""
    kw = PPOTrainConfig().env_kwargs
    assert kw["building"] == "procedural" and kw["building_seeds"] == SPLITS["train"].building_seeds
    assert not set(kw["building_seeds"]) & (set(SPLITS["val"].building_seeds) | set(SPLITS["test"].building_seeds))
    assert {k: kw[k] for k in BENCHMARK_TASK} == dict(BENCHMARK_TASK)
    assert (kw["depth_shape"], kw["depth_dtype"], kw["goal_format"], kw["observe_scan"]) == ((60, 80), "uint8", "polar", 40)


def test_bad_env_kwarg_fails_before_training(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="max_steps"):
        train_ppo(config_with(PPOTrainConfig(out=str(tmp_path / "x")), max_steps=0))
    with pytest.raises(InputError, match="unknown argument 'nope'"):
        train_ppo(config_with(PPOTrainConfig(out=str(tmp_path / "x")), nope=1))
    assert not (tmp_path / "x").exists()
    (tmp_path / "file").write_text("")
    with pytest.raises(InputError, match="'out'.*cannot make the directory"):
        train_ppo(PPOTrainConfig(out=str(tmp_path / "file" / "run")))


@needs_gl
def test_bad_policy_kwargs_are_an_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="'policy_kwargs'.*nope"):
        train_ppo(tiny(tmp_path / "x", n_envs=1, policy_kwargs={"nope": 1}))


def test_load_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such policy directory"):
        SB3Policy.load(tmp_path / "none")
    d = tmp_path / "p"
    d.mkdir()
    (d / "model.zip").write_bytes(b"not a zip file")
    with pytest.raises(InputError, match="no policy.json"):
        SB3Policy.load(d)
    (d / "policy.json").write_text("{not json")
    with pytest.raises(InputError, match="not a readable policy.json"):
        SB3Policy.load(d)
    (d / "policy.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(InputError, match="not a depthnav policy file"):
        SB3Policy.load(d)
    (d / "policy.json").write_text(json.dumps({"format": "depthnav-sb3-policy", "version": 1, "algorithm": "PPO", "observation": {}}))
    with pytest.raises(InputError, match="not a readable stable-baselines3 PPO model") as e:
        SB3Policy.load(d)
    assert "\n" not in str(e.value)
    (d / "model.zip").unlink()
    with pytest.raises(InputError, match="no model.zip"):
        SB3Policy.load(d)


@pytest.mark.parametrize(
    "argv, pattern",
    [
        (["--steps", "0", "--out", "{tmp}/a"], "--steps: expected an integer >= 1"),
        (["--steps", "10", "--out", "{tmp}/a", "--n-envs", "0"], "--n-envs"),
        (["--steps", "10", "--out", "{tmp}/a", "--eval-episodes", "-1"], "--eval-episodes"),
        (["--steps", "10", "--out", "{tmp}/a", "--learning-rate", "nan"], "--learning-rate"),
        (["--steps", "10", "--out", "{tmp}/a", "--vec", "fork"], "--vec"),
        (["--steps", "ten", "--out", "{tmp}/a"], "--steps"),
        (["--out", "{tmp}/a"], "--steps"),
        (["--steps", "10", "--out", "{tmp}/a", "--resume"], "nothing to resume"),
        (["--steps", "10", "--out", "{tmp}/a", "--resume", "--n-epochs", "3"], "--n-epochs: a resumed run keeps"),
        (["--steps", "10", "--out", "{tmp}/a", "--log-std-init", "inf"], "--log-std-init: expected a finite number"),
        (["--steps", "10", "--out", "{tmp}/a", "--resume", "--end-on-collision"], "--end-on-collision: a resumed run keeps"),
    ],
)
def test_cli_errors(tmp_path: Path, capsys, argv, pattern) -> None:
    assert main(["train", "ppo", *(a.replace("{tmp}", str(tmp_path)) for a in argv)]) == 2
    assert pattern in err_line(capsys)


def test_cli_training_choices_reach_the_config(tmp_path: Path, monkeypatch, capsys) -> None:
    """--end-on-collision ends the training env's episodes at a collision and --log-std-init
    sets the policy's initial spread; without them, the benchmark task and SB3's default."""
    import sim.rl.ppo as ppo

    seen = []

    def fake(cfg, **kw):
        seen.append(cfg)
        raise KeyboardInterrupt

    monkeypatch.setattr(ppo, "train_ppo", fake)
    argv = ["train", "ppo", "--steps", "10", "--out", str(tmp_path / "a")]
    assert main([*argv, "--end-on-collision", "--log-std-init", "-1"]) == 130
    assert main(argv) == 130
    chosen, plain = seen
    assert chosen.env_kwargs["terminate_on_collision"] is True and chosen.policy_kwargs == {"log_std_init": -1.0}
    assert plain.env_kwargs["terminate_on_collision"] is False and plain.policy_kwargs == {}
    assert {k: v for k, v in chosen.env_kwargs.items() if k != "terminate_on_collision"} == {
        k: v for k, v in plain.env_kwargs.items() if k != "terminate_on_collision"
    }


def test_cli_help_defaults_are_the_config_defaults() -> None:
    """The defaults the help names are PPOTrainConfig's."""
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices["train"]
    ppo = next(a for a in sub._actions if a.dest == "train_command").choices["ppo"]
    cfg = PPOTrainConfig()
    names = {f.name for f in fields(cfg)}
    checked = 0
    for action in ppo._actions:
        m = re.search(r"\(default (\S+?)[;)]", action.help or "")
        if m and action.dest in names:
            assert float(m.group(1)) == float(getattr(cfg, action.dest)), action.dest
            checked += 1
    assert checked >= 7
