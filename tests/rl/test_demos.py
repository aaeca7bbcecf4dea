"""Expert demonstrations (sim.rl.demos) and behaviour cloning (sim.rl.bc): the dataset's
layout, its agreement with an independent replay of the env, the loader's errors, an
interrupted recording, the CLI, and a behaviour-cloning smoke test that has to beat
predicting the mean action on held-out episodes."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")  # the rl extra

from autonomy.common.errors import InputError  # noqa: E402
from sim.cli import main  # noqa: E402
from sim.rl.bc import BCPolicy, train_bc  # noqa: E402
from sim.rl.demo_recording import record_demonstrations  # noqa: E402
from sim.rl.demos import Demonstrations, load_demonstrations  # noqa: E402
from sim.rl.splits import BENCHMARK_TASK, LEARNER_OBS, SPLITS, episode_specs  # noqa: E402
from tests.helpers import GL, err_line  # noqa: E402

needs_gl = pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")

MAX_STEPS = 40


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> tuple[Path, Demonstrations]:
    if not GL:
        pytest.skip("no OpenGL (EGL/OSMesa) context on this machine")
    out = tmp_path_factory.mktemp("demos") / "two.npz"
    d = record_demonstrations("train", episodes=2, seed=3, out=out, env_kwargs={"max_steps": MAX_STEPS}, progress=False)
    return out, d


def _env(building_seed: int, max_steps: int = MAX_STEPS):
    """The recorded episode's env, spelled out here rather than through the recorder."""
    import gymnasium as gym

    import sim  # noqa: F401

    kw = {**BENCHMARK_TASK, **LEARNER_OBS, "max_steps": max_steps, "stack_policy": True}
    return gym.make("DepthNav-v0", building="procedural", building_seeds=(building_seed,), **kw)


@needs_gl
def test_the_file_is_plain_numpy_with_the_documented_layout(recorded) -> None:
    path, rec = recorded
    with np.load(path, allow_pickle=False) as z:  # no project import needed to read it
        f = {k: z[k] for k in z.files}
    n, e = len(f["actions"]), 2
    assert f["episode_lengths"].tolist() == [MAX_STEPS, MAX_STEPS] and n == 2 * MAX_STEPS
    assert f["episode_starts"].tolist() == [0, MAX_STEPS] and f["episode_starts"].dtype == np.int64
    expect = {"depth": ((60, 80, 1), np.uint8), "goal": ((2,), np.float32), "odometry": ((3,), np.float32), "scan": ((40,), np.float32)}
    for k, (shape, dt) in expect.items():
        assert f[f"obs/{k}"].shape == (n, *shape) and f[f"obs/{k}"].dtype == dt, k
        assert f[f"final_obs/{k}"].shape == (e, *shape) and f[f"final_obs/{k}"].dtype == dt, k
    assert f["actions"].shape == (n, 3) and f["actions"].dtype == np.float32
    assert np.all(np.abs(f["actions"]) <= 1.0)
    assert f["rewards"].shape == (n,) and f["rewards"].dtype == np.float32
    assert f["terminations"].dtype == bool and f["truncations"].dtype == bool
    # Each episode ends at its last step and nowhere before (40 steps: truncated, not arrived).
    done = f["terminations"] | f["truncations"]
    assert np.flatnonzero(done).tolist() == [MAX_STEPS - 1, 2 * MAX_STEPS - 1]
    specs = episode_specs("train", 2, 3)
    assert f["building_seed"].tolist() == [SPLITS["train"].building_seeds[0], SPLITS["train"].building_seeds[1]]
    assert f["reset_seed"].tolist() == [s.reset_seed for s in specs]
    assert f["success"].dtype == bool and f["spl"].shape == (e,)
    meta = json.loads(str(f["meta"]))
    assert meta["format"] == "depthnav-demonstrations" and meta["version"] == 1 and not meta["interrupted"]
    assert meta["policy"] == "classical" and meta["split"] == "train" and meta["seed"] == 3
    assert meta["env_kwargs"]["stack_policy"] is True and meta["env_kwargs"]["max_steps"] == MAX_STEPS
    assert meta["observation_keys"] == ["depth", "goal", "odometry", "scan"] and "uint8" in meta["observation_space"]
    # The loader gives the same arrays, and episodes() slices them at the boundaries.
    d = load_demonstrations(path)
    assert d.n_steps == n and d.n_episodes == e
    np.testing.assert_array_equal(d.observations["depth"], rec.observations["depth"])
    eps = list(d.episodes())
    assert [len(x) for x in eps] == [MAX_STEPS, MAX_STEPS]
    np.testing.assert_array_equal(eps[1].actions, f["actions"][MAX_STEPS:])
    np.testing.assert_array_equal(eps[1].final_observation["scan"], f["final_obs/scan"][1])


@needs_gl
def test_a_replay_of_the_actions_reproduces_every_observation(recorded) -> None:
    """An independent env, reset with the episode's seed and stepped with the stored
    actions, sees the stored observations bit for bit; each stored action is the stack's
    action of that step (as float32); rewards and episode ends agree."""
    _, d = recorded
    nxt = d.next_observations()
    for ep in d.episodes():
        env = _env(ep.building_seed)
        try:
            obs, info = env.reset(seed=ep.reset_seed)
            s = int(d.episode_starts[list(d.reset_seed).index(ep.reset_seed)])
            for t in range(len(ep)):
                for k in obs:
                    np.testing.assert_array_equal(obs[k], ep.observations[k][t], err_msg=f"{k} at step {t}")
                assert np.array_equal(ep.actions[t], np.asarray(info["stack_action"], dtype=np.float32)), t
                obs, reward, term, trunc, info = env.step(ep.actions[t])
                assert np.float32(reward) == ep.rewards[t] and term == ep.terminations[t] and trunc == ep.truncations[t]
                for k in obs:
                    np.testing.assert_array_equal(obs[k], nxt[k][s + t], err_msg=f"next {k} at step {t}")
            for k in obs:
                np.testing.assert_array_equal(obs[k], ep.final_observation[k])
            assert info["success"] == ep.success
        finally:
            env.close()


def _write(path: Path, **arrays) -> Path:
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


@needs_gl
def test_the_loader_names_the_file_and_the_problem(recorded, tmp_path: Path) -> None:
    path, _ = recorded
    with np.load(path) as z:
        good = {k: z[k] for k in z.files}
    meta = json.loads(str(good["meta"]))
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"\x00not a zip file" * 10)
    cases = {
        tmp_path / "missing.npz": "not found",
        garbage: "not an .npz archive",
        tmp_path: "a directory, not a demonstrations file",
        _write(tmp_path / "nometa.npz", actions=good["actions"]): "no 'meta' entry",
        _write(tmp_path / "other.npz", **{**good, "meta": np.array(json.dumps({**meta, "format": "x"}))}): "not a depthnav demonstrations file",
        _write(tmp_path / "v99.npz", **{**good, "meta": np.array(json.dumps({**meta, "version": 99}))}): "version 99",
        _write(tmp_path / "noactions.npz", **{k: v for k, v in good.items() if k != "actions"}): "no 'actions' entry",
        _write(tmp_path / "tiles.npz", **{**good, "episode_lengths": good["episode_lengths"] + 1}): "do not tile",
        _write(tmp_path / "short.npz", **{**good, "obs/scan": good["obs/scan"][:-1]}): "obs/scan has",
    }
    for p, words in cases.items():
        with pytest.raises(InputError) as exc:
            load_demonstrations(p)
        msg = str(exc.value)
        assert str(p) in msg and words in msg and "\n" not in msg, msg


@needs_gl
def test_an_interrupted_recording_keeps_the_finished_episodes(tmp_path: Path, monkeypatch) -> None:
    import sim.rl.demo_recording as rec

    real = rec.run_episode
    calls = []

    def run_episode(env, policy, spec, on_step=None):
        calls.append(spec.index)
        if len(calls) == 2:  # a few steps into the second episode, then Ctrl-C
            def interrupting(*a):
                on_step(*a)
                if len(seen) == 5:
                    raise KeyboardInterrupt
                seen.append(1)
            seen: list[int] = []
            return real(env, policy, spec, interrupting)
        return real(env, policy, spec, on_step)

    monkeypatch.setattr(rec, "run_episode", run_episode)
    out = tmp_path / "cut.npz"
    with pytest.raises(KeyboardInterrupt):
        record_demonstrations("train", episodes=3, seed=0, out=out, env_kwargs={"max_steps": 15}, progress=False)
    d = load_demonstrations(out)
    assert d.meta["interrupted"] is True and d.n_episodes == 1 and d.n_steps == 15
    assert [p.name for p in tmp_path.iterdir()] == ["cut.npz"]  # no temporary file left


def test_demos_cli_errors(tmp_path: Path, capsys) -> None:
    bad = [
        (["demos", "record", "--episodes", "0", "--out", str(tmp_path / "a.npz")], "--episodes"),
        (["demos", "record", "--split", "nope", "--out", str(tmp_path / "a.npz")], "split 'nope'"),
        (["demos", "record", "--out", str(tmp_path / "a.txt")], ".npz"),
        (["demos", "record", "--max-steps", "0", "--out", str(tmp_path / "a.npz")], "--max-steps"),
        (["demos", "bc", str(tmp_path / "none.npz"), "--out", str(tmp_path / "m")], "not found"),
        (["demos"], "demos"),
    ]
    for argv, words in bad:
        assert main(argv) == 2, argv
        assert words in err_line(capsys), argv
    assert not list(tmp_path.iterdir())


def test_record_output_errors_come_before_any_episode(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    (tmp_path / "dir.npz").mkdir()
    for out, words in ((tmp_path / "file" / "a.npz", "cannot make the directory"), (tmp_path / "dir.npz", "is a directory")):
        with pytest.raises(InputError, match=words) as exc:
            record_demonstrations("train", episodes=1, out=out, progress=False)
        assert str(out) in str(exc.value)


@needs_gl
def test_demos_record_cli(tmp_path: Path, capsys) -> None:
    out = tmp_path / "sub" / "one.npz"
    assert main(["demos", "record", "--split", "val", "--episodes", "1", "--seed", "2", "--max-steps", "8", "--out", str(out), "--no-progress"]) == 0
    assert f"wrote {out}: 1 episodes, 8 steps" in capsys.readouterr().out
    d = load_demonstrations(out)
    assert d.meta["split"] == "val" and d.building_seed.tolist() == [SPLITS["val"].building_seeds[0]]
    assert d.reset_seed.tolist() == [episode_specs("val", 1, 2)[0].reset_seed]


@needs_gl
def test_bc_cli_arguments_and_a_saved_policy(recorded, tmp_path: Path, capsys) -> None:
    path, d = recorded
    for argv, words in ((["--epochs", "0"], "--epochs"), (["--lr", "-1"], "--lr"), (["--batch-size", "0"], "--batch-size")):
        assert main(["demos", "bc", str(path), "--out", str(tmp_path / "m"), *argv]) == 2
        assert words in err_line(capsys)
    assert main(["demos", "bc", str(path), "--epochs", "2", "--batch-size", "32", "--out", str(tmp_path / "m")]) == 0
    out = capsys.readouterr().out
    assert "epoch 2: train loss" in out and "predicting the mean" in out and f"wrote {tmp_path / 'm'}" in out
    # The saved policy predicts as the trained one (same seed: training is deterministic).
    pol, hist = train_bc(d, epochs=2, batch_size=32, seed=0, lr=1e-3)
    loaded = BCPolicy.load(tmp_path / "m")
    np.testing.assert_array_equal(loaded.predict(d.observations), pol.predict(d.observations))
    from sim.rl.policy_specs import make_policy

    by_spec = make_policy(f"bc:{tmp_path / 'm'}")
    np.testing.assert_array_equal(by_spec.predict(d.observations), pol.predict(d.observations))
    assert json.loads((tmp_path / "m" / "policy.json").read_text())["history"]["train_loss"] == hist["train_loss"]
    assert loaded.env_kwargs() == dict(LEARNER_OBS)  # the tuples EnvConfig has, not JSON's lists
    # A Policy the evaluation runs: a few steps on an env with its observations.
    from sim.rl.evaluate import run_episode

    env = _env(d.building_seed[0].item(), max_steps=5)
    try:
        r = run_episode(env, loaded, episode_specs("train", 1, 3)[0])
    finally:
        env.close()
    assert r.steps == 5
    with pytest.raises(InputError, match="not a behaviour-cloning model"):
        BCPolicy.load(tmp_path)


def test_bc_files_of_the_wrong_kind(tmp_path: Path) -> None:
    """A PPO directory given to BCPolicy (and a BC one to SB3Policy) says which it is; a
    save over a PPO run or under a file is refused by name; train_bc wants a dataset."""
    from sim.rl.bc import BCNet
    from sim.rl.sb3 import SB3Policy

    pol = BCPolicy(BCNet((60, 80), 46, np.zeros(46), np.ones(46)), dict(LEARNER_OBS))
    bc_dir = pol.save(tmp_path / "bc")
    assert sorted(p.name for p in bc_dir.iterdir()) == ["model.pt", "policy.json"]  # no temporary file left
    with pytest.raises(InputError, match=f"behaviour-cloning model.*bc:{bc_dir}"):
        SB3Policy.load(bc_dir)
    ppo_dir = tmp_path / "ppo"
    ppo_dir.mkdir()
    (ppo_dir / "model.zip").write_bytes(b"")
    (ppo_dir / "policy.json").write_text(json.dumps({"format": "depthnav-sb3-policy", "version": 1}))
    with pytest.raises(InputError, match=f"stable-baselines3 policy.*ppo:{ppo_dir}"):
        BCPolicy.load(ppo_dir)
    with pytest.raises(InputError, match="holds a stable-baselines3 policy"):
        pol.save(ppo_dir)
    with pytest.raises(InputError, match="no such behaviour-cloning model directory"):
        BCPolicy.load(bc_dir / "model.pt")
    with pytest.raises(InputError, match="cannot make the directory"):
        pol.save(bc_dir / "model.pt" / "x")
    with pytest.raises(InputError, match="demos: expected a Demonstrations"):
        train_bc(str(tmp_path / "d.npz"))


@needs_gl
@pytest.mark.slow
def test_bc_learns_the_expert_better_than_its_mean_action(tmp_path: Path) -> None:
    """Trained on 10 short episodes of the stack, the training loss falls to a fraction of
    its initial value and the held-out episodes' MSE clearly beats predicting the
    training set's mean action, which a network that learnt nothing would match (as it
    does on shuffled actions)."""
    d = record_demonstrations("train", episodes=10, seed=0, out=tmp_path / "ten.npz", env_kwargs={"max_steps": 120}, progress=False)
    _, h = train_bc(d, epochs=6, batch_size=64, seed=0, lr=1e-3)
    assert h["train_loss"][-1] < 0.5 * h["train_mse_initial"], h
    assert h["heldout_episodes"] == 2 and h["train_episodes"] == 8
    assert min(h["heldout_loss"]) < 0.7 * h["heldout_mean_baseline"], h
    assert h["heldout_loss"][-1] < h["heldout_mean_baseline"], h
    _, h2 = train_bc(d, epochs=1, batch_size=64, seed=0, lr=1e-3)
    assert h2["train_loss"][0] == h["train_loss"][0]  # the same seed, the same run
    # The control: the same actions shuffled across steps carry no relation to the
    # observations, and the same training does not beat the mean on held-out episodes.
    perm = np.random.default_rng(1).permutation(d.n_steps)
    _, hc = train_bc(dataclasses.replace(d, actions=d.actions[perm]), epochs=6, batch_size=64, seed=0, lr=1e-3)
    assert min(hc["heldout_loss"]) > 0.9 * hc["heldout_mean_baseline"], hc


@needs_gl
def test_a_decision_level_task_records_its_own_observations_and_clones_them(tmp_path: Path, capsys) -> None:
    """On DepthNavLocal-v0 the dataset holds the task's terms (no depth image), the cloned
    policy remembers its task, reloads to the same predictions and runs in the evaluation
    on that task; the CLI records and trains it."""
    from sim.envs.tasks import LOCALNAV
    from sim.rl.evaluate import policy_task, run_episode
    from sim.rl.policy_specs import make_policy

    assert main(["demos", "record", "--task", "DepthNav-v9", "--out", str(tmp_path / "x.npz")]) == 2
    assert "--task DepthNav-v9: expected one of" in err_line(capsys)

    out = tmp_path / "local.npz"
    assert main(["demos", "record", "--task", LOCALNAV, "--episodes", "3", "--seed", "1", "--max-steps", "12", "--out", str(out), "--no-progress"]) == 0
    assert f"steps of the classical stack on {LOCALNAV} train" in capsys.readouterr().out
    d = load_demonstrations(out)
    assert d.meta["task"] == LOCALNAV and "depth" not in d.observations
    assert set(d.observations) == {"goal", "odometry", "plan", "ranges", "velocity"} and d.n_steps == 36
    assert main(["demos", "bc", str(out), "--epochs", "2", "--batch-size", "16", "--out", str(tmp_path / "m")]) == 0
    loaded = BCPolicy.load(tmp_path / "m")
    assert loaded.task == LOCALNAV and policy_task(loaded) == LOCALNAV and loaded.net.depth_hw is None
    pol, _ = train_bc(d, epochs=2, batch_size=16, seed=0, lr=1e-3)
    np.testing.assert_array_equal(make_policy(f"bc:{tmp_path / 'm'}").predict(d.observations), pol.predict(d.observations))
    from sim.envs.depthnav import make
    from sim.rl.evaluate import episode_env_kwargs

    spec = episode_specs("train", 1, 1)[0]
    env = make(LOCALNAV, **{**episode_env_kwargs(loaded, spec.building_seed, None, LOCALNAV), "max_steps": 4})
    try:
        assert run_episode(env, loaded, spec).steps == 4
    finally:
        env.close()
    with pytest.raises(InputError, match="--task DepthNav-v0: policy bc:.* trained on DepthNavLocal-v0"):
        policy_task(loaded, "DepthNav-v0")
    fewer = {k: (v[:, :1] if k == "ranges" else v) for k, v in d.observations.items()}
    with pytest.raises(InputError, match="features, the network was trained on"):
        loaded.predict(fewer)


@needs_gl
@pytest.mark.slow
def test_bc_on_a_decision_level_task_learns_the_expert_better_than_its_mean_action(tmp_path: Path) -> None:
    """The same check as on DepthNav-v0, on DepthNavLocal-v0's vector observations."""
    d = record_demonstrations("train", episodes=10, seed=0, out=tmp_path / "ten.npz", env_kwargs={"max_steps": 40},
                              progress=False, task="DepthNavLocal-v0")
    _, h = train_bc(d, epochs=8, batch_size=32, seed=0, lr=1e-3)
    assert h["task"] == "DepthNavLocal-v0" and h["train_loss"][-1] < 0.5 * h["train_mse_initial"], h
    assert min(h["heldout_loss"]) < 0.7 * h["heldout_mean_baseline"], h
    perm = np.random.default_rng(1).permutation(d.n_steps)
    _, hc = train_bc(dataclasses.replace(d, actions=d.actions[perm]), epochs=8, batch_size=32, seed=0, lr=1e-3)
    assert min(hc["heldout_loss"]) > 0.9 * hc["heldout_mean_baseline"], hc


@needs_gl
@pytest.mark.skipif(importlib.util.find_spec("minari") is None, reason="minari (optional) not installed")
def test_minari_export_round_trip(recorded, tmp_path: Path, monkeypatch) -> None:
    """Minari (optional) gets every episode's T + 1 observations, actions and ends, raw."""
    import minari

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    from sim.rl.demos import export_minari

    _, d = recorded
    export_minari(d, "depthnav/test-v0")
    ds = minari.load_dataset("depthnav/test-v0")
    assert ds.total_episodes == 2 and ds.total_steps == d.n_steps
    for mep, ep in zip(ds.iterate_episodes(), d.episodes(), strict=True):
        for k, v in ep.observations.items():
            np.testing.assert_array_equal(mep.observations[k][:-1], v)
            np.testing.assert_array_equal(mep.observations[k][-1], ep.final_observation[k])
        np.testing.assert_array_equal(mep.actions, ep.actions)
        np.testing.assert_array_equal(mep.truncations, ep.truncations)
    assert ds.recover_environment().unwrapped.config.depth_shape == (60, 80)
    with pytest.raises(InputError, match="already exists"):
        export_minari(d, "depthnav/test-v0")
    for bad in ("noversion", "a/b-v0", "x/y z-v1"):
        with pytest.raises(InputError, match="expected an id"):
            export_minari(d, bad)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["depthnav"]  # nothing made for them
