"""Policy-research tooling around ``DepthNav-v0``: building splits and the benchmark task
(:mod:`sim.rl.splits`), its frozen val and test episodes (:mod:`sim.rl.benchmark_episodes`,
written by :mod:`sim.rl.freeze_episodes`), policies (:mod:`sim.rl.policies`, made from a spec by
:mod:`sim.rl.policy_specs`), the standard evaluation (:mod:`sim.rl.evaluate`), PPO
(:mod:`sim.rl.ppo`, saved as :mod:`sim.rl.sb3` loads it), demonstrations (the dataset,
:mod:`sim.rl.demos`; its recording, :mod:`sim.rl.demo_recording`) and behaviour cloning
(:mod:`sim.rl.bc`). Nothing here imports torch or stable-baselines3 at package import;
docs/rl.md has the overview.
"""
