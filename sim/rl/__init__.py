"""Policy-research tooling around ``DepthNav-v0``: building splits and the benchmark task
(:mod:`sim.rl.splits`), policies (:mod:`sim.rl.policies`), the standard evaluation
(:mod:`sim.rl.evaluate`), and PPO, demonstrations and behaviour cloning. Nothing here
imports torch or stable-baselines3 at package import; docs/rl.md has the overview.
"""
