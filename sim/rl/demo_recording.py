"""Recording expert demonstrations: :func:`record_demonstrations` runs
:class:`sim.rl.policies.ClassicalPolicy` over a split's :func:`sim.rl.splits.episode_specs`
through :func:`sim.rl.evaluate.run_episode`, with the learned-policy observations
(:data:`sim.rl.splits.LEARNER_OBS`), and writes the dataset of :mod:`sim.rl.demos`.

The actions are the stack's float64 ``info["stack_action"]`` rounded to float32 (the
action space's type) *before* the env is stepped, so every stored action is exactly the
one applied and replaying them from the reset seed reproduces every observation bit for
bit (stepping with the float64 action and storing it rounded does not: the runs part
within tens of steps).

This module sits above the evaluation it runs, and the dataset's module below behaviour
cloning, which reads the dataset and is itself a policy the evaluation loads.
"""

from __future__ import annotations

import datetime as _dt
import os
from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.files import output_path
from sim.envs.tasks import POINTNAV_V0
from sim.rl.demos import _EPISODE_FIELDS, FORMAT, VERSION, Demonstrations
from sim.rl.evaluate import episode_env_kwargs, run_episode, run_episodes
from sim.rl.policies import ClassicalPolicy
from sim.rl.splits import LEARNER_OBS, benchmark_task, episode_specs, get_split


class _Expert:
    """The classical stack (:class:`sim.rl.policies.ClassicalPolicy`) with the learned-policy
    observations (on ``DepthNav-v0``; a decision-level task fixes its own), acting in
    float32 so that the stored actions are exactly the applied ones."""

    def __init__(self, task: str = POINTNAV_V0) -> None:
        self._policy = ClassicalPolicy()
        self.name = self._policy.name
        self._env_kwargs = {**(LEARNER_OBS if task == POINTNAV_V0 else {}), **self._policy.env_kwargs()}

    def env_kwargs(self) -> dict[str, Any]:
        return dict(self._env_kwargs)

    def reset(self, seed: int) -> None:
        self._policy.reset(seed)

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        return np.asarray(self._policy.act(obs, info), dtype=np.float32)


class _EpisodeBuffer:
    """The steps of the episode being recorded (an ``on_step`` callback)."""

    def __init__(self) -> None:
        self.obs: list[dict[str, np.ndarray]] = []
        self.actions: list[np.ndarray] = []
        self.rewards: list[float] = []
        self.terminations: list[bool] = []
        self.truncations: list[bool] = []
        self.final_obs: dict[str, np.ndarray] = {}

    def __call__(self, obs, action, reward, next_obs, terminated, truncated, info) -> None:
        self.obs.append(obs)
        self.actions.append(action)
        self.rewards.append(reward)
        self.terminations.append(terminated)
        self.truncations.append(truncated)
        self.final_obs = next_obs

    def arrays(self, space) -> dict[str, Any]:
        """The episode as arrays: obs per key in the space's dtype, final obs, actions, ..."""
        keys = list(space.spaces)
        return {
            "obs": {k: np.stack([o[k] for o in self.obs]).astype(space[k].dtype, copy=False) for k in keys},
            "final_obs": {k: np.asarray(self.final_obs[k], dtype=space[k].dtype) for k in keys},
            "actions": np.stack(self.actions).astype(np.float32, copy=False),
            "rewards": np.asarray(self.rewards, dtype=np.float32),
            "terminations": np.asarray(self.terminations, dtype=bool),
            "truncations": np.asarray(self.truncations, dtype=bool),
        }


def record_demonstrations(
    split: str = "train",
    episodes: int = 100,
    seed: int = 0,
    out: str | os.PathLike[str] = "demos.npz",
    env_kwargs: Mapping[str, Any] | None = None,
    progress: bool = True,
    task: str = POINTNAV_V0,
) -> Demonstrations:
    """Record the classical stack on the ``episodes`` episodes of
    :func:`sim.rl.splits.episode_specs` (split, seed) of the registered ``task``
    (:mod:`sim.envs.tasks`) with its learned-policy observations and write them to ``out``
    (this module's ``.npz`` layout, atomically). ``env_kwargs`` override env arguments
    (e.g. ``max_steps`` for a short test).

    On a KeyboardInterrupt the finished episodes are written (``meta["interrupted"]``
    true; nothing is written when none finished) and the interrupt goes on.
    Returns the dataset as written."""
    sp = get_split(split)
    specs = episode_specs(sp, episodes, seed)
    if Path(out).suffix != ".npz":
        raise InputError(f"out: expected a file name ending in .npz, got {str(out)!r}")
    benchmark_task(task)  # an unknown task fails before any work
    p = output_path(out)
    expert = _Expert(task)
    shown = {k: v for k, v in episode_env_kwargs(expert, specs[0].building_seed, env_kwargs, task).items() if k != "building_seeds"}
    meta: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "policy": expert.name,
        "task": task,
        "split": sp.name,
        "split_building_seeds": list(sp.building_seeds),
        "seed": int(seed),
        "episodes_requested": int(episodes),
        "env_kwargs": shown,
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "depthnav_version": _package_version(),
    }
    done: list[tuple[Any, dict[str, Any]]] = []  # (EpisodeResult, arrays)

    def record(env: Any, s: Any) -> Any:
        if "observation_space" not in meta:
            meta["observation_space"] = str(env.observation_space)
            meta["action_space"] = str(env.action_space)
            meta["observation_keys"] = list(env.observation_space.spaces)
        buf = _EpisodeBuffer()
        result = run_episode(env, expert, s, on_step=buf)
        done.append((result, buf.arrays(env.observation_space)))
        return result

    try:
        for _ in run_episodes(expert, specs, env_kwargs, episode=record, progress=progress, desc=f"demos on {sp.name}", task=task):
            pass  # record() keeps each episode
    except KeyboardInterrupt:
        if done:
            _assemble(done, {**meta, "interrupted": True}).save(p)
        raise
    demos = _assemble(done, {**meta, "interrupted": False})
    demos.save(p)
    return demos


def _assemble(done: list[tuple[Any, dict[str, Any]]], meta: dict[str, Any]) -> Demonstrations:
    """One dataset of the finished episodes, in episode-index order."""
    done = sorted(done, key=lambda d: d[0].index)
    results = [r for r, _ in done]
    eps = [a for _, a in done]
    keys = list(eps[0]["obs"])
    lengths = np.array([len(a["actions"]) for a in eps], dtype=np.int64)

    def cat(name: str) -> np.ndarray:
        return np.concatenate([a[name] for a in eps])

    return Demonstrations(
        observations=MappingProxyType({k: np.concatenate([a["obs"][k] for a in eps]) for k in keys}),
        actions=cat("actions"),
        rewards=cat("rewards"),
        terminations=cat("terminations"),
        truncations=cat("truncations"),
        final_observations=MappingProxyType({k: np.stack([a["final_obs"][k] for a in eps]) for k in keys}),
        episode_starts=np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64),
        episode_lengths=lengths,
        **{k: np.array([getattr(r, k) for r in results], dtype=dt) for k, dt in _EPISODE_FIELDS.items() if k != "episode_index"},
        episode_index=np.array([r.index for r in results], dtype=np.int64),
        meta=MappingProxyType({**meta, "episodes": len(results), "steps": int(lengths.sum())}),
    )


def _package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("depthnav")
    except PackageNotFoundError:
        return "unknown"
