"""Scene building blocks: the cuboid, wall and corridor rigs of PlaneMap's experiments.

Import ``sim`` (not ``mujoco``) first: the package sets the headless GL backend.
"""
