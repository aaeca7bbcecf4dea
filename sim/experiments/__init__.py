"""Scenario kinds and their runs: the closed-loop runner, missions, the localization comparison, the plane-mapping experiments, sweeps and recorded drives."""
