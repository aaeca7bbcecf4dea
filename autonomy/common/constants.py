"""Physical constants of the robot and its depth camera, each written once.

The configuration dataclasses take their defaults from here (the papers' robot: a
CoBot-style round base with a Kinect v1, docs/architecture.md).
"""

ROBOT_RADIUS_M = 0.3
"""Radius of the round base (m)."""

SAFETY_MARGIN_M = 0.1
"""Clearance the obstacle avoidance keeps beyond the robot's radius (m); the navigation
graph made from the walls keeps the same, so that every edge is one the avoidance lets
the robot pass."""

KINECT_MIN_RANGE_M = 0.8
"""The Kinect v1 measures nothing closer than this (m)."""

KINECT_MAX_RANGE_M = 4.0
"""... nor farther than this: the end of its valid range (m)."""

KINECT_FOCAL_PX = 580.0
"""Focal length of the Kinect v1 depth camera at 640 x 480, in pixels (fx = fy)."""
