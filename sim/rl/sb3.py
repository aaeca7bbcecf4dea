"""A saved stable-baselines3 policy as a :class:`sim.rl.policies.Policy`.

A saved policy is a directory with ``model.zip`` (the SB3 model, as ``model.save`` writes
it) and ``policy.json`` (what it was trained on: the observation settings, the whole env
keyword arguments, the training configuration and the steps done), as
:func:`sim.rl.ppo.train_ppo` writes it. The evaluation builds its env with
:meth:`SB3Policy.env_kwargs`, so the policy sees observations of the shape it was trained on.
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.base_class import BaseAlgorithm

from autonomy.common.errors import InputError
from sim.rl.policy_files import BC_MODEL_FILE, POLICY_FILE, SB3_FORMAT, SB3_MODEL_FILE

MODEL_FILE = SB3_MODEL_FILE
#: Written into policy.json; a reader refuses other formats.
FORMAT = SB3_FORMAT
FORMAT_VERSION = 1
#: EnvConfig fields that shape what a policy observes: a saved policy's env_kwargs() are
#: the ones of these it was trained with (the task and buildings are the evaluation's).
OBSERVATION_FIELDS = (
    "depth_shape",
    "depth_layout",
    "depth_dtype",
    "goal_format",
    "goal_from_truth",
    "observe_points",
    "observe_scan",
    "observe_pose_estimate",
    "scan_min_height_m",
    "scan_max_height_m",
    "observe_depth",
    "observe_ranges",
    "ranges_max_m",
    "observe_plan",
    "plan_spacing_m",
    "observe_velocity",
    "history",
    "goal_scale_m",
)
#: EnvConfig fields that say how a policy's action is carried out: a saved policy's
#: env_kwargs() include the ones of these it was trained with (it is evaluated the way it
#: learnt to drive).
ACTION_FIELDS = ("safety_layer",)
ALGORITHMS: dict[str, type[BaseAlgorithm]] = {"PPO": PPO}


def observation_kwargs(env_kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """The observation settings among env keyword arguments (see OBSERVATION_FIELDS)."""
    return {k: env_kwargs[k] for k in OBSERVATION_FIELDS if k in env_kwargs}


def to_json(value: Any) -> Any:
    """Env kwargs and configs as JSON: tuples as lists, dataclasses as dicts, others as repr."""
    import dataclasses

    if isinstance(value, Mapping):
        return {str(k): to_json(v) for k, v in value.items()}
    if isinstance(value, tuple | list):
        return [to_json(v) for v in value]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_json(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return repr(value)


def env_value(value: Any) -> Any:
    """An env kwarg from JSON: lists back to the tuples EnvConfig fields are (a dataclass
    value, written as a dict, stays a dict and EnvConfig rejects it by name)."""
    if isinstance(value, list):
        return tuple(env_value(v) for v in value)
    return value


class SB3Policy:
    """A trained stable-baselines3 model acting deterministically (the mean action)."""

    def __init__(self, model: BaseAlgorithm, meta: Mapping[str, Any], path: Path) -> None:
        self.model = model
        self.meta = dict(meta)
        self.path = path
        self.name = f"{str(meta.get('algorithm', 'sb3')).lower()}:{path}"
        self.task = str(meta.get("task", "DepthNav-v0"))
        """The registered task it was trained on (:mod:`sim.envs.tasks`), evaluated on by default."""

    @classmethod
    def load(cls, path: str | Path, torch_threads: int | None = 1) -> SB3Policy:
        """The policy saved in directory ``path`` (model.zip + policy.json).

        ``torch_threads`` sets torch's intra-op threads for this process (one is fastest
        for one observation at a time; None leaves it alone).
        """
        d = Path(path)
        if not d.is_dir():
            raise InputError(f"{d}: no such policy directory (expected one with {MODEL_FILE} and {POLICY_FILE}, as `depthnav train ppo` writes)")
        if not (d / MODEL_FILE).exists() and (d / BC_MODEL_FILE).is_file():
            raise InputError(f"{d}: a behaviour-cloning model, not a stable-baselines3 policy (evaluate it as bc:{d})")
        for name in (POLICY_FILE, MODEL_FILE):
            if not (d / name).is_file():
                raise InputError(f"{d}: no {name} (a saved policy directory holds {MODEL_FILE} and {POLICY_FILE}, as `depthnav train ppo` writes)")
        meta = read_policy_json(d / POLICY_FILE)
        algo = ALGORITHMS.get(str(meta.get("algorithm")))
        if algo is None:
            raise InputError(f"{d / POLICY_FILE}: algorithm {meta.get('algorithm')!r} unknown (expected one of: {', '.join(ALGORITHMS)})")
        if torch_threads is not None:
            torch.set_num_threads(int(torch_threads))
        try:
            model = algo.load(d / MODEL_FILE, device="cpu")
        except (zipfile.BadZipFile, ValueError, KeyError, RuntimeError, EOFError, OSError) as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise InputError(f"{d / MODEL_FILE}: not a readable stable-baselines3 {algo.__name__} model ({first})") from None
        return cls(model, meta, d)

    def env_kwargs(self) -> dict[str, Any]:
        """The observation settings the policy was trained with and how its actions were
        carried out (EnvConfig fields: OBSERVATION_FIELDS, ACTION_FIELDS)."""
        trained = self.meta.get("env_kwargs") or {}
        action = {k: env_value(trained[k]) for k in ACTION_FIELDS if k in trained}
        return {**{k: env_value(v) for k, v in self.meta["observation"].items()}, **action}

    def reset(self, seed: int) -> None:
        """Nothing to reset: the policy is feed-forward and deterministic."""

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        """The deterministic action (the Gaussian's mean, clipped to [-1, 1]), shape (3,)."""
        action, _ = self.model.predict(obs, deterministic=True)
        return np.clip(np.asarray(action, dtype=np.float32).reshape(-1), -1.0, 1.0)


def read_policy_json(path: Path) -> dict[str, Any]:
    """policy.json, checked for its format; a broken file is a one-line InputError."""
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not a readable policy.json ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise InputError(f"{path}: not a depthnav policy file (expected \"format\": \"{FORMAT}\")")
    if meta.get("version") != FORMAT_VERSION:
        raise InputError(f"{path}: policy format version {meta.get('version')!r} unsupported (expected {FORMAT_VERSION})")
    if not isinstance(meta.get("observation"), dict):
        raise InputError(f"{path}: no \"observation\" settings (the env kwargs the policy was trained with)")
    return meta
