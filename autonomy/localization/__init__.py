"""Where the robot is: the observation model and Corrective Gradient Refinement on the
vector map, the lost detector (health, view check, missing walls) and relocalization on
the whole map (scans, straight runs, active localization)."""
