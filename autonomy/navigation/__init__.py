"""How the robot moves: obstacle avoidance, the memory of obstacles out of view and the
navigator that follows plans on the graph."""
