"""The env's rerun recording (``EnvConfig.rrd``): every step streamed to an .rrd file."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from autonomy.perception.camera import CameraIntrinsics
from sim.envs.config import EnvConfig
from sim.envs.loop import Reading
from sim.envs.site import Site
from sim.envs.task import Episode

if TYPE_CHECKING:
    from sim.viz.recording import Recorder


class EnvRecording:
    """Streams the env's steps to a :class:`sim.viz.recording.Recorder`, made on first use
    (in the process that steps the env, so the env pickles before its first reset); the
    heavy items (depth, FSPF, particles, people) every ``rrd_every`` steps."""

    def __init__(self, config: EnvConfig, intrinsics: CameraIntrinsics, frame_dt: float) -> None:
        self.config = config
        self.intrinsics = intrinsics
        self.frame_dt = frame_dt
        self._recorder: Recorder | None = None
        self._frame = 0
        self._time = 0.0
        self._site: Site | None = None
        """The site whose map was logged last."""

    def log(self, site: Site, episode: Episode, reading: Reading, new_episode: bool) -> None:
        """Log this step (``new_episode``: the first frame of an episode)."""
        from sim.viz.recording import Recorder

        cfg = self.config
        if self._recorder is None:
            self._recorder = Recorder(cfg.rrd, every=cfg.rrd_every, depth_downsample=1, application_id="depthnav-env")
            self._recorder.log_camera_model(self.intrinsics, cfg.kinect.mount)
            self._recorder.log_robot_shape(cfg.robot.radius_m, cfg.robot.height_m)
        rec = self._recorder
        if site is not self._site:
            rec.log_map(site.building.vectormap, site.building.navgraph, cfg.world.wall_height_m)
            self._site = site
        if new_episode:
            rec.set_time(self._frame, self._time)
            rec.log_waypoints(np.asarray(episode.goal, dtype=np.float64).reshape(1, 2), static=False)
            rec.reset_trajectory()
        self._frame += 1
        self._time += self.frame_dt
        rec.set_time(self._frame, self._time)
        rec.log_pose(self._frame, reading.pose)
        out = reading.output
        if out is not None and out.localizing:
            rec.log_estimate(self._frame, reading.estimate)
        if rec.heavy(self._frame):
            rec.log_depth(reading.depth)
            if out is not None:
                rec.log_fspf(out.perception.planes)
                if out.refinement is not None:
                    rec.log_localization(out.refinement.before, out.refinement.after, out.refinement.weights)
            rec.log_people(site.world.people.positions())
            rec.log_scalars({"env/steps": float(episode.steps), "env/collisions": float(episode.collisions)})

    def close(self) -> None:
        """Close the file; a later step starts a new recording at the same path."""
        if self._recorder is not None:
            self._recorder.close()
            self._recorder = None
