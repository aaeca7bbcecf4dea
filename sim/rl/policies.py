"""Policies that :func:`sim.rl.evaluate.evaluate` runs: the random and classical-stack
baselines, and learned policies by spec (``make_policy("ppo:PATH")``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from autonomy.common.errors import InputError


@runtime_checkable
class Policy(Protocol):
    """What the evaluation needs of a policy."""

    name: str

    def env_kwargs(self) -> dict[str, Any]:
        """EnvConfig fields the policy needs (observations, ``stack_policy``); not the task."""
        ...

    def reset(self, seed: int) -> None:
        """Start an episode (``seed``: the episode's reset seed, for policies that draw)."""
        ...

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        """The action, shape (3,) in [-1, 1], for the observation and info of the last step."""
        ...


class RandomPolicy:
    """Uniform random actions in [-1, 1]^3 every step (the chance baseline)."""

    def __init__(self, seed: int = 0) -> None:
        self.name = "random" if seed == 0 else f"random:{seed}"
        self.seed = int(seed)
        self._rng = np.random.default_rng([self.seed, 0])

    def env_kwargs(self) -> dict[str, Any]:
        return {}

    def reset(self, seed: int) -> None:
        # Per episode, so an episode's actions do not depend on which episodes ran before.
        self._rng = np.random.default_rng([self.seed, int(seed)])

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        return self._rng.uniform(-1.0, 1.0, 3)


class ClassicalPolicy:
    """The project's robot stack (FSPF, CGR, avoidance, navigator) as a policy: the env
    runs it with ``stack_policy=True`` and the policy steps with ``info["stack_action"]``."""

    name = "classical"

    def env_kwargs(self) -> dict[str, Any]:
        return {"stack_policy": True}

    def reset(self, seed: int) -> None:
        pass

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        return info["stack_action"]


POLICY_SPECS = "'random', 'random:SEED', 'classical', 'ppo:PATH' or 'bc:PATH' (a saved model directory)"


def make_policy(spec: str) -> Policy:
    """A policy from its spec: 'random' (or 'random:SEED'), 'classical', 'ppo:PATH'
    (``sim.rl.sb3.SB3Policy.load(PATH)``) or 'bc:PATH' (``sim.rl.bc.BCPolicy.load(PATH)``),
    the last two imported only then."""
    kind, _, arg = str(spec).partition(":")
    if kind == "random":
        if not arg:
            return RandomPolicy()
        try:
            seed = int(arg)
        except ValueError:
            seed = -1
        if seed < 0:
            raise InputError(f"policy {spec!r}: expected random:SEED with an integer SEED >= 0")
        return RandomPolicy(seed)
    if kind == "classical" and not arg:
        return ClassicalPolicy()
    if kind in ("ppo", "bc"):
        if not arg:
            raise InputError(f"policy {spec!r}: expected {kind}:PATH, the directory of a saved model")
        if not Path(arg).exists():
            raise InputError(f"policy {spec!r}: {arg} not found (expected the directory of a saved model)")
        if kind == "bc":
            from sim.rl.bc import BCPolicy

            return BCPolicy.load(arg)
        from sim.rl.sb3 import SB3Policy

        return SB3Policy.load(arg)
    raise InputError(f"policy {spec!r} unknown (expected {POLICY_SPECS})")
