"""A micro-task a working learner must solve within minutes: the reward, observation and
action plumbing's end-to-end check.

The task is the shipped ``small_floor``'s corridor: start and goal on its centre line
(the seven graph nodes along y = 5.1 m), 2-6 m apart, the start heading drawn at random,
no people, no furniture, 100 decisions (20 s). With the goal in the corridor the robot
must turn to it and drive without scraping the walls, which no shape test checks: a sign
error in the reward, an observation in the wrong frame or an action scaled wrong keeps
PPO's success near chance. :func:`check_learnability` trains the reference recipe of a
task (:data:`sim.rl.ppo.RECIPES`) on it for a fixed number of decisions and evaluates the
deterministic policy on held-out episodes.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from sim.envs.tasks import LOCALNAV

#: The corridor nodes of small_floor (x from 1.1 to 10.0 m at y = 5.1 m).
CORRIDOR_NODES = (22, 0, 8, 4, 12, 23, 24)

MICRO_TASK: dict[str, Any] = dict(
    building="small_floor",
    start_nodes=CORRIDOR_NODES,
    goal_nodes=CORRIDOR_NODES,
    min_goal_distance_m=2.0,
    max_goal_distance_m=6.0,
    n_people=0,
    n_furniture=0,
    max_steps=100,
)
"""EnvConfig fields of the micro-task (on top of the task's registration)."""

EVAL_SEED = 10_000
"""Reset seeds of the held-out episodes: EVAL_SEED + k (training draws its own)."""


def check_learnability(
    out: str | Path, task: str = LOCALNAV, steps: int = 12_288, episodes: int = 10, seed: int = 0
) -> dict[str, float]:
    """Train the reference PPO recipe of ``task`` on :data:`MICRO_TASK` for ``steps``
    decisions (one env in this process) into ``out``, then run the deterministic policy
    on ``episodes`` held-out episodes; returns their success rate, collisions per episode
    and the training's wall time (s)."""
    from sim.envs.depthnav import make
    from sim.rl.ppo import PPOTrainConfig, train_ppo
    from sim.rl.sb3 import SB3Policy

    cfg = PPOTrainConfig.for_task(
        task, out=str(out), env_kwargs=MICRO_TASK, n_envs=1, vec="dummy", total_steps=steps, eval_episodes=0,
        checkpoint_every=10**9, seed=seed,
    )
    t0 = time.perf_counter()
    train_ppo(cfg)
    train_s = time.perf_counter() - t0
    policy = SB3Policy.load(out)
    env = make(task, **MICRO_TASK)
    successes = collisions = 0
    try:
        for k in range(episodes):
            obs, info = env.reset(seed=EVAL_SEED + k)
            done = False
            while not done:
                obs, _, term, trunc, info = env.step(policy.act(obs, info))
                done = term or trunc
            successes += bool(info["success"])
            collisions += int(info["collisions"])
    finally:
        env.close()
    return {"success": successes / episodes, "collisions": collisions / episodes, "train_s": train_s}
