"""Train PPO on the train split's buildings, then evaluate it on the val split.

The same as ``depthnav train ppo --steps 20000 --out runs/ppo_example`` followed by
``depthnav eval --policy ppo:runs/ppo_example``; docs/rl.md has the full run.
"""

from sim.rl.evaluate import evaluate
from sim.rl.ppo import PPOTrainConfig, train_ppo
from sim.rl.sb3 import SB3Policy


def main() -> None:
    cfg = PPOTrainConfig(out="runs/ppo_example", total_steps=20_000, eval_episodes=0)
    result = train_ppo(cfg, progress=True, log=print)
    print(f"{result.steps} steps in {result.wall_s:.0f} s ({result.fps:.0f} steps/s)")
    report = evaluate(SB3Policy.load(cfg.out), split="val", episodes=8)
    print(report.table())


if __name__ == "__main__":  # needed: the envs run in spawned processes
    main()
