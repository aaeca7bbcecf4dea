"""The metrics a mission run's ``report.json`` holds, each with what it measures.

:func:`sim.experiments.metrics.run_metrics` writes them (a test checks that it writes no
other); a scenario's ``[expect]`` names them (:mod:`sim.experiments.expect`). Some are
there only when they were measured: the localization figures when localization runs,
the fault figures when faults are injected, the recording's when one is written.
"""

from __future__ import annotations

METRICS: dict[str, str] = {
    # The drive
    "frames": "Kinect frames simulated (30 a second)",
    "distance_m": "distance the robot drove",
    "duration_s": "simulated time",
    "collisions": "contacts of the base with anything (each onset counts)",
    "collisions_wall": "... with a wall",
    "collisions_furniture": "... with furniture",
    "collisions_person": "... with a person",
    "collision_incidents": "contacts grouped into incidents (onsets close in time count once)",
    "waypoints_reached": "waypoints the robot reached",
    "waypoints_failed": "waypoints not reached in time, or reached at the wrong place",
    "waypoints_unvisited": "waypoints the run ended before",
    "realtime_factor": "simulated seconds per wall-clock second",
    "wall_time_s": "wall-clock time of the loop",
    # Localization against the truth
    "resets": "localization failures (error above localization.reset_error_m)",
    "resets_per_km": "resets per km driven",
    "truth_resets_needed": "failures the robot did not recover from in time, ended by resetting the belief to the truth",
    "loc_failures": "localization failures, any cause",
    "loc_failures_faults": "... of them caused by an injected fault",
    "lost_alarms": "times the robot said it was lost",
    "lost_false_alarms": "... while its error was below 0.5 m",
    "lost_misses": "failures the robot never noticed",
    "relocalizations": "global relocalizations",
    "recovered_by_robot": "failures the robot ended itself",
    "recovery_time_median_s": "median time from a failure to its end by the robot",
    "recovery_time_max_s": "longest time from a failure to its end by the robot",
    "notice_time_median_s": "median time from a failure to the robot's lost alarm",
    "frames_dropped": "frames the stack rejected as dropped",
    "frames_stale": "... as stale",
    "frames_invalid": "... as invalid",
    "frames_corrupt": "... as corrupt",
    "relocalizing_frames": "frames spent relocalizing",
    "blind_frames": "frames with no wall in view to localize on",
    "loc_error_mean_m": "mean position error of the estimate",
    "loc_error_median_m": "median position error",
    "loc_error_p95_m": "95th percentile of the position error",
    "loc_error_max_m": "largest position error",
    "loc_heading_error_mean_deg": "mean heading error",
    "blind_share": "share of the distance driven blind",
    "blind_stretch_max_m": "longest stretch driven blind",
    # Injected faults
    "faults_injected": "faults injected",
    "faults_recovered": "faults the robot recovered from",
    "kidnappings": "kidnappings",
    "kidnappings_recovered": "kidnappings the robot recovered from without truth",
    "kidnap_recovery_median_s": "median time to recover from a kidnapping",
    "kidnap_recovery_max_s": "longest time to recover from a kidnapping",
    # Perception
    "fspf_plane_points_mean": "FSPF plane-filtered points per frame",
    "fspf_outliers_mean": "FSPF outlier points per frame",
    "fspf_planes_mean": "FSPF planes per frame",
    "fspf_points_2d_mean": "2D points per frame handed to localization",
    # The rerun recording
    "recording_flush_s": "time to flush the recording at the end",
    "logging_overhead": "the recording's share of the loop's time",
}
