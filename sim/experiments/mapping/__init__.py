"""PlaneMap's three experiments as scenario kinds, one module each.

- :mod:`.cuboid` (``mapping_cuboid``), I, cuboid angle (III-A, Table II): a cuboid seen
  from the four arm views of Table I; both detectors report the angle between the two
  side faces they find.
- :mod:`.wall` (``mapping_wall``), II, wall distance (III-B, Table III): the camera
  facing a flat wall at 1.06 m and 1.56 m; the standard deviation of the error in rho of
  the wall's points.
- :mod:`.corridor` (``mapping_corridor``), III, corridor mapping (III-C, IV-C): the
  robot drives a corridor loop (:mod:`.loop_driver`) with the camera looking right;
  planes from both detectors are registered into octree maps at the odometry pose (no
  loop closure), exported and drawn (:mod:`.plane_maps`); time to the first plane, per
  plane, and the maps' sizes.

:mod:`.common` holds what they share (the configuration header, the detectors' call,
how a loop stops), :mod:`.driver` the run, sweep trial and summary of any of them.
"""
