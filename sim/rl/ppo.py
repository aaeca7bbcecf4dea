"""PPO (Schulman et al. 2017) on ``DepthNav-v0`` with stable-baselines3, resumable.

:func:`train_ppo` trains SB3's ``MultiInputPolicy`` (NatureCNN on the uint8 depth image,
which SB3 normalises by 255; the goal, odometry and scan flattened beside it) on the
benchmark task over the train split's buildings, and writes to ``cfg.out``:

- ``model.zip`` + ``policy.json``: the saved policy (:class:`sim.rl.sb3.SB3Policy` loads
  it; ``policy.json`` holds the env kwargs, the configuration and the steps done), every
  ``checkpoint_every`` steps, at the end and on Ctrl-C; ``vecnormalize.pkl``: the reward
  normalisation's running statistics, for resuming;
- ``progress.csv`` and ``curve.png``: the learning curve, one row per rollout;
- ``eval.json``: the final policy on the validation split (:func:`sim.rl.evaluate.evaluate`).

``resume=True`` continues from the checkpoint in ``out`` up to ``total_steps`` in all.
"""

from __future__ import annotations

import csv
import json
import math
import os
import sys
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize

from autonomy.common.errors import InputError
from autonomy.common.files import atomic_write, atomic_write_text, output_path
from sim.rl.evaluate import evaluate
from sim.rl.sb3 import (
    FORMAT,
    FORMAT_VERSION,
    MODEL_FILE,
    POLICY_FILE,
    SB3Policy,
    env_value,
    observation_kwargs,
    read_policy_json,
    to_json,
)
from sim.rl.splits import LEARNER_OBS, split_env_kwargs

VECNORM_FILE = "vecnormalize.pkl"
PROGRESS_FILE = "progress.csv"
CURVE_FILE = "curve.png"
EVAL_FILE = "eval.json"
#: Episodes the curve's means and success rate are taken over.
WINDOW = 100
#: progress.csv's columns: the learning curve, then SB3's training statistics of the
#: update before the row (empty before the first update).
COLUMNS = (
    "timesteps", "episodes", "ep_return_mean", "success_rate", "ep_len_mean", "collisions_mean",
    "wall_s", "fps", "approx_kl", "clip_fraction", "entropy_loss", "value_loss", "explained_variance",
)
_TRAIN_STATS = {
    "approx_kl": "train/approx_kl", "clip_fraction": "train/clip_fraction", "entropy_loss": "train/entropy_loss",
    "value_loss": "train/value_loss", "explained_variance": "train/explained_variance",
}
VEC_KINDS = ("dummy", "subproc")
#: Settings a resumed run takes from its checkpoint (the model was built with them).
HYPERPARAMETERS = (
    "n_steps", "batch_size", "n_epochs", "learning_rate", "gamma", "gae_lambda", "clip_range", "ent_coef",
    "vf_coef", "max_grad_norm", "normalize_reward", "policy_kwargs",
)


def train_env_kwargs(task: str = "DepthNav-v0") -> dict[str, Any]:
    """The training env of ``task``: the benchmark task on the train split, with the
    learner observations on ``DepthNav-v0`` (the decision-level tasks' own are fixed by
    their registration)."""
    if task == "DepthNav-v0":
        return split_env_kwargs("train", **LEARNER_OBS)
    return split_env_kwargs("train", task)


#: The reference recipe's settings per decision-level task (the rest are the defaults):
#: a two-layer 256-unit MLP on the vector observations, 512-decision rollouts per env,
#: ten epochs, and a small entropy bonus so the 5 Hz commands keep exploring.
RECIPES: Mapping[str, Mapping[str, Any]] = {
    task: {"n_steps": 512, "batch_size": 256, "n_epochs": 10, "ent_coef": 0.005, "policy_kwargs": {"net_arch": [256, 256]}}
    for task in ("DepthNavPointGoal-v0", "DepthNavLocal-v0")
}

#: The recipe's training env settings per task, over its env_kwargs: training episodes
#: end at the first collision. The task's collision term (-1 once per contact, at most
#: 5) keeps one pinned episode from drowning the others, but it is cheap next to 1 a
#: metre of progress, and a policy that scrapes along walls on its way still gains;
#: ending the episode costs it the rest of the route and the arrival. The evaluation
#: counts collisions without ending episodes.
RECIPE_ENV: Mapping[str, Mapping[str, Any]] = {
    task: {"terminate_on_collision": True} for task in ("DepthNavPointGoal-v0", "DepthNavLocal-v0")
}


@dataclass(frozen=True)
class PPOTrainConfig:
    """A PPO training run: SB3's PPO hyper-parameters, the vector env and the outputs."""

    out: str = "runs/ppo"
    """Output directory (model.zip, policy.json, progress.csv, curve.png, eval.json)."""
    task: str = "DepthNav-v0"
    """The registered task trained on (:mod:`sim.envs.tasks`); :meth:`for_task` gives its recipe."""
    total_steps: int = 500_000
    """Environment steps in all (a resumed run continues up to this)."""
    n_envs: int = 2
    """Environments stepped together (one per core)."""
    vec: str = "subproc"
    """'subproc': one spawned process per env (SubprocVecEnv); 'dummy': all in this process."""
    n_steps: int = 1024
    """Steps per env per rollout (PPO's horizon T); a rollout is n_steps * n_envs steps."""
    batch_size: int = 256
    """Minibatch size of the updates."""
    n_epochs: int = 4
    """Passes over each rollout (PPO's K)."""
    learning_rate: float = 3e-4
    """Adam step size (constant)."""
    gamma: float = 0.99
    """Discount."""
    gae_lambda: float = 0.95
    """GAE's lambda."""
    clip_range: float = 0.2
    """PPO's clipping epsilon."""
    ent_coef: float = 0.0
    """Entropy bonus weight."""
    vf_coef: float = 0.5
    """Value loss weight."""
    max_grad_norm: float = 0.5
    """Gradient clipping norm."""
    normalize_reward: bool = True
    """Scale rewards by a running estimate of the return's spread (SB3's VecNormalize,
    rewards only: the sparse +-10 success and collision rewards against 0.025-a-step progress)."""
    seed: int = 0
    """Seed of the policy's initialisation, action sampling and the envs (env i: seed + i)."""
    torch_threads: int = 1
    """torch intra-op threads in the learner (the envs take the other core)."""
    checkpoint_every: int = 20_000
    """Save model.zip, policy.json and curve.png every this many steps."""
    eval_episodes: int = 50
    """Episodes of the final evaluation on the val split (0: none)."""
    env_kwargs: dict[str, Any] | None = None
    """``sim.envs.depthnav.make(task, **env_kwargs)``; None: :func:`train_env_kwargs`, the
    benchmark task on the train split (on ``DepthNav-v0`` with the learner observations)."""
    policy_kwargs: dict[str, Any] = field(default_factory=dict)
    """SB3's policy_kwargs (e.g. ``net_arch``); default SB3's MultiInputPolicy."""
    eval_env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Overrides of the final evaluation's env (e.g. a shorter ``max_steps`` for a test);
    empty: the benchmark task."""

    def __post_init__(self) -> None:
        def need(ok: bool, name: str, what: str) -> None:
            if not ok:
                raise InputError(f"PPOTrainConfig: '{name}' expected {what}, got {getattr(self, name)!r}")

        def is_int(v: Any) -> bool:
            return isinstance(v, int | np.integer) and not isinstance(v, bool)

        def is_num(v: Any) -> bool:
            return isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool) and math.isfinite(v)

        for name in ("total_steps", "n_envs", "n_steps", "batch_size", "n_epochs", "torch_threads", "checkpoint_every"):
            need(is_int(getattr(self, name)) and getattr(self, name) >= 1, name, "an integer >= 1")
        need(is_int(self.seed) and self.seed >= 0, "seed", "an integer >= 0")
        need(is_int(self.eval_episodes) and self.eval_episodes >= 0, "eval_episodes", "an integer >= 0 (0: no evaluation)")
        need(isinstance(self.vec, str) and self.vec in VEC_KINDS, "vec", "'dummy' or 'subproc'")
        need(isinstance(self.normalize_reward, bool | np.bool_), "normalize_reward", "True or False")
        need(self.n_steps >= 2, "n_steps", "an integer >= 2")
        need(1 < self.batch_size <= self.n_steps * self.n_envs, "batch_size", f"an integer in [2, n_steps * n_envs = {self.n_steps * self.n_envs}]")
        need(is_num(self.learning_rate) and self.learning_rate > 0, "learning_rate", "a positive number")
        need(is_num(self.gamma) and 0 < self.gamma <= 1, "gamma", "a number in (0, 1]")
        need(is_num(self.gae_lambda) and 0 <= self.gae_lambda <= 1, "gae_lambda", "a number in [0, 1]")
        need(is_num(self.clip_range) and self.clip_range > 0, "clip_range", "a positive number")
        for name in ("ent_coef", "vf_coef", "max_grad_norm"):
            need(is_num(getattr(self, name)) and getattr(self, name) >= 0, name, "a number >= 0")
        need(isinstance(self.out, str | os.PathLike) and str(self.out) != "", "out", "an output directory")
        from sim.envs.tasks import TASKS

        need(isinstance(self.task, str) and self.task in TASKS, "task", f"one of {', '.join(TASKS)}")
        if self.env_kwargs is None:
            object.__setattr__(self, "env_kwargs", train_env_kwargs(self.task))
        need(isinstance(self.env_kwargs, Mapping), "env_kwargs", "a mapping of EnvConfig fields")
        need(isinstance(self.policy_kwargs, Mapping), "policy_kwargs", "a mapping")
        need(isinstance(self.eval_env_kwargs, Mapping), "eval_env_kwargs", "a mapping of EnvConfig fields")
        object.__setattr__(self, "out", str(self.out))
        object.__setattr__(self, "env_kwargs", dict(self.env_kwargs))
        object.__setattr__(self, "policy_kwargs", dict(self.policy_kwargs))
        object.__setattr__(self, "eval_env_kwargs", dict(self.eval_env_kwargs))

    @classmethod
    def for_task(cls, task: str = "DepthNav-v0", **changes: Any) -> PPOTrainConfig:
        """The reference recipe of ``task`` (:data:`RECIPES`, and :data:`RECIPE_ENV` over
        the env arguments: ``changes``' ``env_kwargs`` or :func:`train_env_kwargs`), then
        ``changes``."""
        env = changes.pop("env_kwargs", None)
        env = {**(train_env_kwargs(task) if env is None else env), **RECIPE_ENV.get(task, {})}
        return cls(task=task, **{**RECIPES.get(task, {}), **changes, "env_kwargs": env})

    @property
    def rollout_steps(self) -> int:
        """Steps per rollout (and per row of progress.csv)."""
        return self.n_steps * self.n_envs


@dataclass(frozen=True)
class TrainResult:
    """What :func:`train_ppo` did."""

    out: Path
    steps: int
    """Environment steps done in all (this run and any it resumed)."""
    episodes: int
    wall_s: float
    """Wall time of training in all, as policy.json records it at the last checkpoint (without the final evaluation)."""
    session_steps: int
    """Steps of this call."""
    session_wall_s: float
    interrupted: bool
    eval_summary: dict[str, Any] | None
    """The final evaluation's summary (None when skipped or interrupted)."""

    @property
    def fps(self) -> float:
        """Steps per second of this call."""
        return self.session_steps / self.session_wall_s if self.session_wall_s > 0 else 0.0


def make_env(env_kwargs: Mapping[str, Any], task: str = "DepthNav-v0"):
    """One monitored env of ``task`` (module level, so spawned workers import it by name),
    with gymnasium's ``TimeLimit`` at its own ``max_steps`` (:func:`sim.envs.depthnav.make`)."""
    from sim.envs.depthnav import make

    return Monitor(make(task, **env_kwargs))


def make_vec_env(cfg: PPOTrainConfig) -> VecEnv:
    """The training VecEnv: n_envs DepthNav envs, in spawned processes for 'subproc' (a
    forked child of a process that has rendered cannot render)."""
    from functools import partial

    fns = [partial(make_env, cfg.env_kwargs, cfg.task) for _ in range(cfg.n_envs)]
    if cfg.vec == "subproc":
        return SubprocVecEnv(fns, start_method="spawn")
    return DummyVecEnv(fns)


class _Curve(BaseCallback):
    """The learning curve (progress.csv, curve.png), checkpoints and the progress display."""

    def __init__(self, cfg: PPOTrainConfig, out: Path, save: Callable[[], None], start_steps: int,
                 start_episodes: int, start_wall_s: float, recent: Mapping[str, list], progress: bool,
                 log: Callable[[str], None] | None) -> None:
        super().__init__()
        self.cfg = cfg
        self.out = out
        self.save_checkpoint = save
        self.episodes = start_episodes
        self.wall0 = start_wall_s
        self.t0 = time.perf_counter()
        self.start_steps = start_steps
        self.last_ckpt = start_steps
        self.last_row = (start_steps, start_wall_s)
        # The last WINDOW episodes (carried over a resume through policy.json).
        self.returns: deque[float] = deque(recent.get("returns", ()), maxlen=WINDOW)
        self.lengths: deque[int] = deque(recent.get("lengths", ()), maxlen=WINDOW)
        self.successes: deque[float] = deque(recent.get("successes", ()), maxlen=WINDOW)
        self.collisions: deque[float] = deque(recent.get("collisions", ()), maxlen=WINDOW)
        self.log = log
        self.bar = None
        if progress:
            from tqdm import tqdm

            self.bar = tqdm(total=cfg.total_steps, initial=start_steps, unit="step", dynamic_ncols=True,
                            desc="ppo", file=sys.stderr, mininterval=1.0)

    @property
    def wall_s(self) -> float:
        return self.wall0 + time.perf_counter() - self.t0

    def _on_step(self) -> bool:
        for info, done in zip(self.locals["infos"], self.locals["dones"], strict=True):
            if done and "episode" in info:
                self.episodes += 1
                self.returns.append(float(info["episode"]["r"]))
                self.lengths.append(int(info["episode"]["l"]))
                self.successes.append(float(bool(info.get("is_success", False))))
                self.collisions.append(float(info.get("collisions", 0)))
        if self.bar is not None:
            self.bar.update(self.num_timesteps - self.bar.n)
        return True

    def _on_rollout_end(self) -> None:
        wall = self.wall_s
        steps0, wall0 = self.last_row
        stats = self.model.logger.name_to_value
        row: dict[str, Any] = {
            "timesteps": self.num_timesteps,
            "episodes": self.episodes,
            "ep_return_mean": _mean(self.returns),
            "success_rate": _mean(self.successes),
            "ep_len_mean": _mean(self.lengths),
            "collisions_mean": _mean(self.collisions),
            "wall_s": round(wall, 2),
            "fps": round((self.num_timesteps - steps0) / max(wall - wall0, 1e-9), 1),
        }
        for col, key in _TRAIN_STATS.items():
            row[col] = round(float(stats[key]), 6) if key in stats else ""
        self.last_row = (self.num_timesteps, wall)
        append_progress(self.out / PROGRESS_FILE, row)
        if self.bar is not None:
            self.bar.set_postfix_str(f"success {_fmt(row['success_rate'])} return {_fmt(row['ep_return_mean'])}", refresh=False)
        # Checkpoints at the end of a rollout, so the curve drawn holds the latest row.
        if self.num_timesteps - self.last_ckpt >= self.cfg.checkpoint_every:
            self.last_ckpt = self.num_timesteps
            self.save_checkpoint()

    def recent(self) -> dict[str, list]:
        """The episode window, for policy.json."""
        return {"returns": [round(v, 4) for v in self.returns], "lengths": list(self.lengths),
                "successes": list(self.successes), "collisions": list(self.collisions)}

    def summary_line(self) -> str:
        return (f"steps {self.model.num_timesteps}/{self.cfg.total_steps}, episodes {self.episodes}, "
                f"success {_fmt(_mean(self.successes))}, return {_fmt(_mean(self.returns))}, "
                f"length {_fmt(_mean(self.lengths))}, wall {self.wall_s:.0f} s")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _mean(values: deque) -> float | str:
    return round(float(np.mean(values)), 4) if values else ""


def _fmt(v: float | str) -> str:
    return f"{v:.3g}" if isinstance(v, float) else "-"


def append_progress(path: Path, row: Mapping[str, Any]) -> None:
    """One row of the learning curve (the header first when the file is new)."""
    new = not path.exists() or path.stat().st_size == 0
    with path.open("a", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        if new:
            w.writeheader()
        w.writerow({k: row.get(k, "") for k in COLUMNS})


def read_progress(path: str | Path) -> dict[str, np.ndarray]:
    """progress.csv as float columns (NaN for empty cells)."""
    with Path(path).open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    return {c: np.array([float(r[c]) if r.get(c) not in (None, "") else np.nan for r in rows]) for c in COLUMNS}


def plot_curve(progress_csv: str | Path, png: str | Path, title: str = "PPO on DepthNav-v0") -> Path:
    """Draw the learning curve of progress.csv: mean return, success rate and episode
    length over the last 100 episodes against environment steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = read_progress(progress_csv)
    x = c["timesteps"]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
    panels = (
        ("ep_return_mean", "mean episode return", None),
        ("success_rate", "success rate", (-0.02, 1.02)),
        ("ep_len_mean", "mean episode length (steps)", None),
    )
    for ax, (col, label, ylim) in zip(axes, panels, strict=True):
        ax.plot(x, c[col], color="tab:blue", lw=1.5)
        ax.set_xlabel("environment steps")
        ax.set_ylabel(label + f" (last {WINDOW} ep.)")
        ax.grid(alpha=0.3)
        if ylim:
            ax.set_ylim(*ylim)
    if x.size:
        wall = c["wall_s"][-1]
        title += f": {int(x[-1]):,} steps, {int(c['episodes'][-1]):,} episodes, {wall / 60:.1f} min"
    fig.suptitle(title)
    png = atomic_write(png, lambda f: fig.savefig(f, format="png", dpi=100))
    plt.close(fig)
    return png


def save_policy(model: PPO, cfg: PPOTrainConfig, out: Path, *, episodes: int, wall_s: float,
                interrupted: bool = False, venv: VecEnv | None = None, recent: Mapping[str, list] | None = None) -> None:
    """model.zip and policy.json (and the reward statistics), each replaced atomically."""
    atomic_write(out / MODEL_FILE, model.save)
    if isinstance(venv, VecNormalize):
        import pickle

        atomic_write(out / VECNORM_FILE, lambda f: pickle.dump(venv, f))
    meta = {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "algorithm": "PPO",
        "task": cfg.task,
        "policy": "MultiInputPolicy",
        "observation": to_json(observation_kwargs(cfg.env_kwargs)),
        "env_kwargs": to_json(cfg.env_kwargs),
        "config": to_json({k: v for k, v in asdict(cfg).items() if k != "env_kwargs"}),
        "steps": int(model.num_timesteps),
        "episodes": int(episodes),
        "wall_s": round(float(wall_s), 2),
        "interrupted": bool(interrupted),
        "saved": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "recent_episodes": dict(recent or {}),
    }
    atomic_write_text(out / POLICY_FILE, json.dumps(meta, indent=2) + "\n")


def train_ppo(cfg: PPOTrainConfig, resume: bool = False, progress: bool = False,
              log: Callable[[str], None] | None = None) -> TrainResult:
    """Train (or with ``resume`` continue) PPO as ``cfg`` says; see the module docstring.

    ``progress`` shows a tqdm bar on stderr; ``log`` receives one line per checkpoint.
    Ctrl-C saves a checkpoint and returns with ``interrupted=True``.
    """
    from sim.envs.config import EnvConfig
    from sim.envs.tasks import TASKS

    EnvConfig().replace(**{**TASKS[cfg.task], **cfg.env_kwargs})  # a bad env argument fails here, before any worker starts
    out = Path(cfg.out)
    steps0, episodes0, wall0 = 0, 0, 0.0
    recent: dict[str, list] = {}
    if resume:
        if not (out / MODEL_FILE).is_file() or not (out / POLICY_FILE).is_file():
            raise InputError(f"{out}: nothing to resume (no {MODEL_FILE} and {POLICY_FILE}; train without --resume first)")
        meta = read_policy_json(out / POLICY_FILE)
        if meta["observation"] != to_json(observation_kwargs(cfg.env_kwargs)):
            raise InputError(f"{out}: the checkpoint observes {meta['observation']}, this run "
                             f"{to_json(observation_kwargs(cfg.env_kwargs))}; resume with the same observation settings")
        steps0, episodes0, wall0 = int(meta["steps"]), int(meta.get("episodes", 0)), float(meta.get("wall_s", 0.0))
        recent = meta.get("recent_episodes") or {}
        saved = meta.get("config", {})
        differ = [k for k in HYPERPARAMETERS if k in saved and to_json(getattr(cfg, k)) != saved[k]]
        if differ:
            raise InputError(f"{out}: the checkpoint was trained with {', '.join(f'{k}={saved[k]!r}' for k in differ)}; "
                             "resume with its hyper-parameters (resume_config reads them)")
        if steps0 >= cfg.total_steps:
            raise InputError(f"{out}: already {steps0} steps; give more total steps than that to resume")
    elif (out / MODEL_FILE).exists() or (out / PROGRESS_FILE).exists():
        raise InputError(f"{out}: holds a training run already; resume it (--resume) or choose another --out")
    output_path(out, "PPOTrainConfig: 'out'", directory=True)
    torch.set_num_threads(cfg.torch_threads)

    venv: VecEnv = make_vec_env(cfg)
    try:
        if resume:
            if cfg.normalize_reward and (out / VECNORM_FILE).is_file():
                venv = VecNormalize.load(str(out / VECNORM_FILE), venv)
            elif cfg.normalize_reward:
                venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=cfg.gamma)
            model = PPO.load(out / MODEL_FILE, env=venv, device="cpu")
            # A fresh stream per resume: the envs' next episodes differ from the first run's.
            model.set_random_seed(cfg.seed + steps0)
        else:
            if cfg.normalize_reward:
                venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=cfg.gamma)
            try:
                model = PPO(
                    "MultiInputPolicy", venv, n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs,
                    learning_rate=cfg.learning_rate, gamma=cfg.gamma, gae_lambda=cfg.gae_lambda, clip_range=cfg.clip_range,
                    ent_coef=cfg.ent_coef, vf_coef=cfg.vf_coef, max_grad_norm=cfg.max_grad_norm,
                    policy_kwargs=dict(cfg.policy_kwargs) or None, seed=cfg.seed, device="cpu", verbose=0,
                )
            except TypeError as e:  # the one free-form argument: an unknown or mistyped policy keyword
                raise InputError(f"PPOTrainConfig: 'policy_kwargs' {cfg.policy_kwargs!r} rejected by SB3's MultiInputPolicy ({e})") from None
        # policy.json always records this run's configuration (resume: its total_steps).
        cb: _Curve
        # The training time of the last checkpoint: what policy.json says and a resumed run goes on from.
        saved_wall = [wall0]

        def checkpoint(interrupted: bool = False) -> None:
            saved_wall[0] = cb.wall_s
            save_policy(model, cfg, out, episodes=cb.episodes, wall_s=saved_wall[0], interrupted=interrupted, venv=venv,
                        recent=cb.recent())
            if (out / PROGRESS_FILE).exists():
                plot_curve(out / PROGRESS_FILE, out / CURVE_FILE, f"PPO on {cfg.task}")
            if log is not None:
                log(cb.summary_line() + (" (interrupted)" if interrupted else "") + f"; saved {out / MODEL_FILE}")

        cb = _Curve(cfg, out, checkpoint, steps0, episodes0, wall0, recent, progress, log)
        t0 = time.perf_counter()
        interrupted = False
        try:
            model.learn(total_timesteps=cfg.total_steps - steps0, callback=cb, reset_num_timesteps=not resume)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            cb.close()
        session_wall = time.perf_counter() - t0
        if interrupted or cb.last_ckpt != model.num_timesteps:
            checkpoint(interrupted)
        steps, episodes, wall = int(model.num_timesteps), cb.episodes, saved_wall[0]
    finally:
        try:
            venv.close()
        except (EOFError, BrokenPipeError, ConnectionResetError):
            pass  # workers already gone after Ctrl-C
    summary = None
    if not interrupted and cfg.eval_episodes > 0:
        summary = evaluate_saved(out, cfg.eval_episodes, cfg.eval_env_kwargs, progress=progress)
    return TrainResult(out, steps, episodes, wall, steps - steps0, session_wall, interrupted, summary)


def evaluate_saved(out: Path, episodes: int, env_kwargs: Mapping[str, Any] | None = None,
                   progress: bool = False) -> dict[str, Any]:
    """Evaluate the saved policy in ``out`` on the val split, write eval.json, return its summary."""
    report = evaluate(SB3Policy.load(out), split="val", episodes=episodes, env_kwargs=env_kwargs or None,
                      progress=progress, out=out / EVAL_FILE)
    return dict(report.summary)


def resume_config(out: str | Path, **changes: Any) -> PPOTrainConfig:
    """The configuration saved in ``out``/policy.json with ``changes`` (e.g. a larger
    ``total_steps``): what ``train_ppo(cfg, resume=True)`` continues with."""
    if not (Path(out) / POLICY_FILE).is_file():
        raise InputError(f"{out}: nothing to resume (no {POLICY_FILE}; train without --resume first)")
    meta = read_policy_json(Path(out) / POLICY_FILE)
    known = {f.name for f in fields(PPOTrainConfig)}
    saved = {k: v for k, v in meta.get("config", {}).items() if k in known}
    for key in ("env_kwargs", "eval_env_kwargs"):
        saved[key] = {k: env_value(v) for k, v in (meta if key == "env_kwargs" else saved).get(key, {}).items()}
    return PPOTrainConfig(**{**saved, "out": str(out), **changes})


def config_with(cfg: PPOTrainConfig, **env_changes: Any) -> PPOTrainConfig:
    """``cfg`` with some env kwargs changed (e.g. ``max_steps`` for a quick run)."""
    return replace(cfg, env_kwargs={**cfg.env_kwargs, **env_changes})
