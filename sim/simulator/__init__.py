"""The simulated site: worlds from blueprints, the robot, the Kinect model, people and furniture, one simulator step."""
