"""Policies by spec, as the command line and :func:`sim.rl.evaluate.evaluate` name them:
``make_policy("random:3")``, ``make_policy("bc:runs/bc")``.

This module sits above the policies it makes, the baselines (:mod:`sim.rl.policies`) and
the learned ones (:mod:`sim.rl.sb3`, :mod:`sim.rl.bc`). The learned ones import torch
and stable-baselines3 when they are imported, so :func:`make_policy` imports each only
when a spec names it: the baselines and the evaluation run without the rl extra.
"""

from __future__ import annotations

from pathlib import Path

from autonomy.common.errors import InputError
from sim.rl.policies import ClassicalPolicy, Policy, RandomPolicy

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
