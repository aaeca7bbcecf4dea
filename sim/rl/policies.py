"""What a policy is to :func:`sim.rl.evaluate.evaluate` (:class:`Policy`), and the random
and classical-stack baselines. The learned policies (:mod:`sim.rl.sb3`, :mod:`sim.rl.bc`)
follow the same protocol; :func:`sim.rl.policy_specs.make_policy` makes any of them from
a spec such as ``"ppo:PATH"``."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np


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
