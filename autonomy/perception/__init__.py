"""From a depth frame to what the robot sees: the camera model, Fast Sampling Plane
Filtering, the near field for avoidance, floor sight lines and the mount check."""
