"""The files of a saved learned policy's directory, for both kinds: a stable-baselines3
policy (:mod:`sim.rl.sb3`) and a behaviour-cloning network (:mod:`sim.rl.bc`).

Both kinds write ``policy.json`` beside their model file, and each refuses the other's
directory with a message naming the spec that loads it (``ppo:DIR`` or ``bc:DIR``), so
each needs the other's file name and format tag. They live here, below both modules, so
that neither imports the other.
"""

from __future__ import annotations

#: What a policy was trained on (observation settings, env keyword arguments, training).
POLICY_FILE = "policy.json"
#: A stable-baselines3 policy's model, as ``model.save`` writes it.
SB3_MODEL_FILE = "model.zip"
#: Written into a stable-baselines3 policy's policy.json; a reader refuses other formats.
SB3_FORMAT = "depthnav-sb3-policy"
#: A behaviour-cloning network's weights (a torch state dict).
BC_MODEL_FILE = "model.pt"
