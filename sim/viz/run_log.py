"""The rerun recording of a closed-loop mission run (:mod:`sim.experiments.loop`): the
static scene once, then each frame's true pose and estimate and, every ``rrd_every``
frames, the heavy items (depth, FSPF, particles, correspondences, avoidance, people,
the scalars). The entity layout is :mod:`sim.viz.recording`'s."""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from autonomy.maps.navgraph import NavGraph
from autonomy.maps.vectormap import VectorMap
from autonomy.navigation.config import NavCommand
from autonomy.stack import StackOutput
from sim.scenario import Scenario
from sim.simulator.actors import Furniture
from sim.simulator.step import SimFrame
from sim.simulator.world import World

if TYPE_CHECKING:
    from sim.viz.recording import Recorder

#: The health state as a number for the rerun timeline.
HEALTH_CODES = {"ok": 0.0, "blind": 1.0, "lost": 2.0, "relocalizing": 3.0}


def health_scalars(out: StackOutput) -> dict[str, float]:
    """The health signal for the recording's timeline (autonomy.localization.health)."""
    h = out.health_sample
    if h is None:
        return {}
    return {
        "health/state": HEALTH_CODES.get(out.health_state, -1.0),
        "health/explained_fast": h.explained_fast,
        "health/explained_slow": h.explained_slow,
        "health/through_fast": h.through_fast,
        "health/jump_m": h.jump_m,
        "health/view_agree": h.view_agree,
        "health/missing_fast": h.missing_fast,
    }


class RunLogger:
    """Logs one mission run to a rerun recording (an .rrd file or a spawned viewer)."""

    def __init__(self, rec: Recorder, avoidance_radius_m: float) -> None:
        self.rec = rec
        self.avoidance_radius_m = avoidance_radius_m
        """The avoidance's radius, the fan's extent."""

    @classmethod
    def open(
        cls,
        rrd: str | Path | None,
        spawn: bool,
        *,
        scn: Scenario,
        seed: int,
        vectormap: VectorMap,
        navgraph: NavGraph,
        furniture: Sequence[Furniture],
        waypoints_xy: np.ndarray,
    ) -> RunLogger:
        """A recording with the static scene: map, camera, robot, furniture, waypoints."""
        # rerun is imported only by a run that records.
        from sim.viz.recording import Recorder

        rec = Recorder(
            rrd, spawn=spawn, every=scn.report.rrd_every, depth_downsample=scn.report.rrd_depth_downsample, recording_id=f"{scn.name}-{seed}"
        )
        rec.log_map(vectormap, navgraph, scn.world.wall_height_m)
        rec.log_camera_model(scn.kinect.intrinsics, scn.kinect.mount)
        rec.log_robot_shape(scn.robot.radius_m, scn.robot.height_m)
        rec.log_furniture([(np.array([f.x, f.y, f.dims[2] / 2]), np.array(f.dims) / 2, f.yaw) for f in furniture])
        rec.log_waypoints(waypoints_xy)
        return cls(rec, scn.avoidance.radius_m)

    def heavy(self, k: int) -> bool:
        """Whether frame ``k`` gets the heavy items (the stack is asked for its
        correspondences on those frames only)."""
        return self.rec.heavy(k)

    def frame(
        self,
        k: int,
        frame: SimFrame,
        out: StackOutput,
        nav: NavCommand,
        world: World,
        *,
        estimate: np.ndarray | None,
        error_m: float,
        collisions: int,
    ) -> None:
        """Frame ``k``'s pose and ``estimate`` (None: the stack does not localize); every
        ``rrd_every`` frames the heavy items from the stack's output ``out`` on the frame
        (made with its correspondences, :meth:`heavy`), with the true ``error_m`` and
        the contacts so far."""
        rec = self.rec
        rec.set_time(k, frame.t)
        rec.log_pose(k, frame.pose)
        if estimate is not None:
            rec.log_estimate(k, estimate)
        if not rec.heavy(k):
            return
        per = out.perception
        rec.log_depth(frame.depth)
        rec.log_fspf(per.planes)
        if out.refinement is not None:
            rec.log_localization(out.refinement.before, out.refinement.after, out.refinement.weights)
        if out.correspondences is not None:
            lines, idx = out.correspondences
            rec.log_scene(lines, out.estimate, per.points_2d, idx)
        rec.log_near_field(per.near_lines)
        if nav.fan is not None:
            rec.log_avoidance(nav.fan[0], nav.fan[1], nav.theta_star_rad, nav.desired_rad, self.avoidance_radius_m)
        rec.log_people(world.people.positions())
        ms = {f"timing_ms/{name}": v * 1e3 for name, v in {**frame.timings_s, **out.timings_s}.items()}
        rec.log_scalars(
            {
                "speed_mps": float(np.hypot(*world.robot.velocity_body(world.data)[:2])),
                **ms,
                "fspf/plane_points": float(len(per.planes.points)),
                "fspf/points_2d": float(len(per.points_2d)),
                "localization/error_m": error_m,
                "localization/spread_m": out.spread[0] if out.localizing else float("nan"),
                **health_scalars(out),
                "collisions": float(collisions),
            }
        )

    def close(self, viz_s: float, wall_s: float) -> dict:
        """Flush the recording; the logging's share of the loop's time (``viz_s`` of
        ``wall_s`` spent logging frames) with the flush."""
        t_close = time.perf_counter()
        self.rec.close()
        flush_s = time.perf_counter() - t_close
        return {"recording_flush_s": round(flush_s, 3), "logging_overhead": round((viz_s + flush_s) / max(wall_s - viz_s, 1e-9), 4)}
