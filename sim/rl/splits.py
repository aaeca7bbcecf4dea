"""Fixed train / val / test building splits and the benchmark task of ``DepthNav-v0``.

A split is a fixed set of procedural building seeds (the generator's 30 x 24 m floors,
:class:`sim.envs.config.EnvConfig`'s default ``procedural``); the three splits share no
building, so a policy trained on ``train`` is evaluated on floors it has never seen.
:func:`episode_specs` fixes which building and which reset seed each evaluation episode
uses: the same specs give every policy the same buildings, furniture, people, starts and
goals. The val and test episodes the evaluation runs are also frozen in a data file
(:mod:`sim.rl.benchmark_episodes`), so a change here or in the env cannot change the
benchmark unnoticed. docs/rl.md explains the choices.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from autonomy.common.errors import InputError

#: EnvConfig keyword arguments of the benchmark task (the building comes from the split).
#: Goals 3-12 m away along the navigation graph, 1000 steps (33 s at 30 Hz, enough for
#: about 2x the longest route at the stack's cruising speed), two people and three
#: unmapped furniture pieces per episode, and collisions counted instead of ending the
#: episode (Habitat's convention), so a policy's collisions per episode are measured.
BENCHMARK_TASK: Mapping[str, Any] = MappingProxyType(
    dict(
        min_goal_distance_m=3.0,
        max_goal_distance_m=12.0,
        goal_radius_m=0.5,
        max_steps=1000,
        n_people=2,
        n_furniture=3,
        terminate_on_success=True,
        terminate_on_collision=False,
    )
)

def benchmark_task(task: str = "DepthNav-v0") -> dict[str, Any]:
    """:data:`BENCHMARK_TASK` for a registered task (:mod:`sim.envs.tasks`): the same
    buildings, goals, people and furniture, with the task's own step limit (a
    decision-level task's ``max_steps`` counts decisions)."""
    from sim.envs.tasks import TASKS

    if task not in TASKS:
        raise InputError(f"task {task!r} unknown (expected one of: {', '.join(TASKS)})")
    return {**BENCHMARK_TASK, "max_steps": int(TASKS[task].get("max_steps", BENCHMARK_TASK["max_steps"]))}


#: Observation settings for learned policies: a 60 x 80 uint8 depth image with a channel
#: axis (SB3's CnnPolicy normalises it), the goal as (distance, bearing) (Habitat's
#: PointGoal) and a 40-bin scan.
LEARNER_OBS: Mapping[str, Any] = MappingProxyType(
    dict(depth_shape=(60, 80), depth_dtype="uint8", depth_layout="hwc", goal_format="polar", observe_scan=40)
)

#: Environment keys that define the benchmark's task and buildings: evaluation sets them,
#: a policy's own env_kwargs cannot change them.
TASK_KEYS = frozenset(BENCHMARK_TASK) | {"building", "building_seed", "building_seeds", "new_building_every", "procedural"}


@dataclass(frozen=True)
class Split:
    """A named, fixed set of procedural buildings."""

    name: str
    """'train', 'val' or 'test'."""
    building_seeds: tuple[int, ...]
    """Seeds of the procedural generator (``blueprints.generate_building``)."""
    episode_seed: int
    """Mixed into every episode's reset seed, so splits never share an episode draw."""
    description: str
    """One line on what the split is for."""


SPLITS: dict[str, Split] = {
    "train": Split("train", tuple(range(1000, 1016)), 101, "16 buildings for training (and demonstrations)"),
    "val": Split("val", tuple(range(2000, 2004)), 202, "4 buildings for model selection and the default evaluation"),
    "test": Split("test", tuple(range(3000, 3004)), 303, "4 buildings for the final numbers only"),
}


def get_split(name: str | Split) -> Split:
    """The split called ``name`` (a :class:`Split` is returned as it is)."""
    if isinstance(name, Split):
        return name
    if name not in SPLITS:
        raise InputError(f"split {name!r} unknown (expected one of: {', '.join(SPLITS)})")
    return SPLITS[name]


@dataclass(frozen=True)
class EpisodeSpec:
    """One evaluation episode: the building and the ``env.reset`` seed."""

    index: int
    building_seed: int
    reset_seed: int


def episode_specs(split: str | Split, episodes: int, seed: int = 0) -> list[EpisodeSpec]:
    """``episodes`` episodes over the split's buildings in turn (episode k on building
    ``building_seeds[k % n]``), each with a reset seed of (split.episode_seed, seed, k)."""
    sp = get_split(split)
    if isinstance(episodes, bool) or not isinstance(episodes, int | np.integer) or episodes < 1:
        raise InputError(f"episodes: expected an integer >= 1, got {episodes!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed: expected an integer >= 0, got {seed!r}")
    n = len(sp.building_seeds)
    return [
        EpisodeSpec(k, sp.building_seeds[k % n], reset_seed(sp, int(seed), k))
        for k in range(int(episodes))
    ]


def reset_seed(split: Split, seed: int, k: int) -> int:
    """The reset seed of episode ``k``: a hash of (split.episode_seed, seed, k), 0 <= s < 2**63."""
    state = np.random.SeedSequence([split.episode_seed, seed, k]).generate_state(1, np.uint64)[0]
    return int(state >> np.uint64(1))


def split_env_kwargs(split: str | Split, task: str = "DepthNav-v0", **extra: Any) -> dict[str, Any]:
    """Keyword arguments of ``gym.make(task, **kw)`` for episodes over the split's
    buildings (one drawn per episode from its seeds) on the benchmark task
    (:func:`benchmark_task`); ``extra`` (e.g. :data:`LEARNER_OBS`, ``new_building_every``) last."""
    sp = get_split(split)
    return {"building": "procedural", "building_seeds": sp.building_seeds, **benchmark_task(task), **extra}
