"""The reference PPO recipe learns the corridor micro-task in about two minutes
(:mod:`sim.rl.learnability`): it fails when the reward, the observations or the actions
are plumbed wrong, which no shape test notices."""

from __future__ import annotations

import pytest

from tests.helpers import GL

pytest.importorskip("stable_baselines3")
pytestmark = pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")


def test_ppo_learns_the_corridor_micro_task(tmp_path) -> None:
    from sim.rl.learnability import check_learnability

    got = check_learnability(tmp_path / "ppo")
    assert got["success"] >= 0.9, got
    assert got["collisions"] <= 1.0, got
