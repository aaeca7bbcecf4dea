"""ROS 2 bags (rosbag2 in MCAP storage) in and out: a simulated run written as a bag
(:mod:`sim.rosbag.run_bag`), and the robot stack replayed on a robot's bag
(:mod:`sim.rosbag.replay`); docs/rosbag.md."""
