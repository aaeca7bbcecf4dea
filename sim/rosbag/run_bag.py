"""A simulated run as a ROS 2 bag: what the robot sensed, what it believed, and the truth.

:class:`RunBag` is fed every frame of the closed loop (:mod:`sim.experiments.loop`) and
writes the topics of :class:`Topics` (REP-105 frames, :mod:`sim.rosbag.messages`):

- the depth image and its camera info (every frame the camera delivered; a frame a
  fault dropped has none),
- the wheel odometry integrated from where the robot started (``nav_msgs/Odometry``,
  ``odom -> base_link`` on ``/tf``), and ``map -> odom`` from the CGR estimate,
- the CGR estimate with its particles' covariance, the ground truth, the command,
- FSPF's plane-filtered points, a laser scan simulated from the depth image (the
  Kinect-Raster scan of BV2012 VI-A: the image row whose rays are level),
- the vector map's walls as markers, the camera mount on ``/tf_static``, and the run's
  settings and the stack's events as JSON strings (``/depthnav/run``, ``/depthnav/events``).

The run's settings (scenario, seed, start) let :mod:`sim.rosbag.replay` run the robot
stack again on the bag with the same seeds.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from autonomy.common.geometry import compose_pose, relative_pose
from autonomy.localization.scans import ScanConfig, raster_scan, scan_angles
from autonomy.perception.camera import CameraIntrinsics, CameraMount
from autonomy.stack import StackConfig
from sim.config import to_dict
from sim.rosbag import messages as m
from sim.rosbag.writer import BagWriter

#: Version of the bag's layout (topics, frames, the run's settings); written in ``/depthnav/run``.
BAG_LAYOUT = 1


@dataclass(frozen=True)
class Topics:
    """Topic names of a depthnav bag (and the defaults :mod:`sim.rosbag.replay` reads)."""

    depth: str = "/camera/depth/image_raw"
    camera_info: str = "/camera/depth/camera_info"
    odom: str = "/odom"
    tf: str = "/tf"
    tf_static: str = "/tf_static"
    estimate: str = "/cgr/pose"
    truth: str = "/ground_truth"
    points: str = "/fspf/points"
    scan: str = "/scan"
    map: str = "/map/walls"
    cmd_vel: str = "/cmd_vel"
    run: str = "/depthnav/run"
    events: str = "/depthnav/events"


TOPICS = Topics()


class RunBag:
    """Writes a run to ``path`` (``.mcap``), a frame at a time."""

    def __init__(
        self,
        path: str | Path,
        *,
        intrinsics: CameraIntrinsics,
        mount: CameraMount,
        walls: np.ndarray,
        frame_dt: float,
        run_info: dict,
        depth_encoding: str = "32FC1",
        topics: Topics = TOPICS,
    ) -> None:
        if depth_encoding not in m.DEPTH_ENCODINGS:
            raise ValueError(f"depth encoding {depth_encoding!r}: expected one of {', '.join(m.DEPTH_ENCODINGS)}")
        self.bag = BagWriter(path)
        self.topics = topics
        self.intr = intrinsics
        self.mount = mount
        self.walls = np.asarray(walls, dtype=np.float64).reshape(-1, 4)
        self.frame_dt = float(frame_dt)
        self.encoding = depth_encoding
        self.info = {"layout": BAG_LAYOUT, "depth_encoding": depth_encoding, **run_info}
        self.scan_cfg = ScanConfig()
        self.odom = np.zeros(3)
        """The wheel odometry integrated from the start (the odom frame's origin)."""
        self._events = 0
        self._started = False

    def start(self, t: float, depth: np.ndarray | None, truth: np.ndarray, out) -> None:
        """The first frame (seen before anything moved): the static parts and the frame
        itself, with the stack's output ``out`` on it."""
        self._static(t)
        self.frame(t, depth, None, truth, out)

    def _static(self, t: float) -> None:
        ns = m.stamp_ns(t)
        tp = self.topics
        self.bag.write(tp.run, ns, m.string(json.dumps(self.info, sort_keys=True)))
        self.bag.write(tp.tf_static, ns, m.tf_message(m.mount_transforms(ns, self.mount)))
        self.bag.write(tp.map, ns, m.wall_markers(ns, self.walls))
        self._started = True

    def sensor_frame(self, t: float, depth: np.ndarray | None, increment: np.ndarray | None, truth: np.ndarray) -> None:
        """A frame with no robot stack beside it (a recorded drive): the sensors and the truth."""
        if not self._started:
            self._static(t)
        inc = np.zeros(3) if increment is None else np.asarray(increment, dtype=np.float64)
        self.odom = compose_pose(self.odom, inc)
        self._frame(m.stamp_ns(t), depth, inc, None, None, truth, None, None, ())

    def frame(self, t: float, depth: np.ndarray | None, increment: np.ndarray | None, truth: np.ndarray, out) -> None:
        """One frame of the loop: the simulator's ``depth`` (None: dropped), odometry
        ``increment`` and true pose, and the stack's output ``out`` on it (its estimate,
        FSPF's points, the command it decided, its new events)."""
        assert self._started, "RunBag.start first"
        inc = np.zeros(3) if increment is None else np.asarray(increment, dtype=np.float64)
        self.odom = compose_pose(self.odom, inc)
        cov = None
        if out.particles is not None and len(out.particles) > 1:
            cov = np.cov(np.asarray(out.particles)[:, :2].T)
        pts = out.perception.planes.points if (out.perception is not None and depth is not None) else None
        command = None if out.command is None else out.command.velocity
        self._frame(m.stamp_ns(t), depth, inc, out.estimate, (cov, float(out.spread[1])), truth, pts, command, out.events)

    def _frame(self, ns, depth, inc, estimate, spread, truth, points, command, events) -> None:
        tp, b = self.topics, self.bag
        if depth is not None:
            b.write(tp.depth, ns, m.depth_image(ns, depth, self.encoding))
            b.write(tp.camera_info, ns, m.camera_info(ns, self.intr))
            ranges = raster_scan(depth, self.intr, self.mount, self.scan_cfg)
            res = self.scan_cfg.resolution_rad
            b.write(tp.scan, ns, m.laser_scan(ns, ranges, float(scan_angles(self.scan_cfg)[0]), res, 0.0, self.scan_cfg.max_range_m, self.frame_dt))
        b.write(tp.odom, ns, m.odometry(ns, self.odom, inc / self.frame_dt))
        odom_tf = m.planar_transform(ns, m.ODOM_FRAME, m.BASE_FRAME, self.odom)
        if estimate is None:
            b.write(tp.tf, ns, m.tf_message([odom_tf]))
        else:
            est = np.asarray(estimate, dtype=np.float64)
            b.write(tp.tf, ns, m.tf_message([m.planar_transform(ns, m.MAP_FRAME, m.ODOM_FRAME, map_from_odom(est, self.odom)), odom_tf]))
            cov, std_th = spread if spread is not None else (None, 0.0)
            b.write(tp.estimate, ns, m.pose_with_covariance(ns, est, np.zeros((2, 2)) if cov is None else cov, std_th))
        b.write(tp.truth, ns, m.pose_stamped(ns, np.asarray(truth, dtype=np.float64)))
        if points is not None:
            b.write(tp.points, ns, m.point_cloud(ns, points))
        if command is not None:
            b.write(tp.cmd_vel, ns, m.twist_stamped(ns, command))
        for e in events[self._events:]:
            b.write(tp.events, ns, m.string(json.dumps(e, sort_keys=True)))
        self._events = max(self._events, len(events))

    def close(self) -> None:
        self.bag.close()


def robot_side(cfg: StackConfig) -> StackConfig:
    """The stack's configuration with each part as the robot stack declares it (a
    scenario's localization section adds the simulation's own keys: the truth's reset
    threshold, whether the start is known)."""
    parts = {}
    for f in dataclasses.fields(StackConfig):
        v = getattr(cfg, f.name)
        declared = type(getattr(StackConfig(), f.name))
        if dataclasses.is_dataclass(v) and type(v) is not declared:
            v = declared(**{g.name: getattr(v, g.name) for g in dataclasses.fields(declared)})
        parts[f.name] = v
    return StackConfig(**parts)


def open_run_bag(run, path: str | Path, depth_encoding: str = "32FC1") -> RunBag:
    """A :class:`RunBag` for a mission run (:class:`sim.experiments.site.Run`) at its
    start, with the run's settings a replay needs: the seed, the start, the map and the
    robot stack's configuration."""
    scn = run.scn
    building = run.building
    info = {
        "scenario": scn.name,
        "seed": int(run.seed),
        "start_pose": [float(v) for v in run.mission.start_pose],
        "start_known": bool(scn.localization.start_known or not scn.stack_config().recovers),
        "map": str(building.map_path) if building.map_path else "",
        "frame_rate_hz": float(scn.kinect.rate_hz),
        "stack": to_dict(robot_side(scn.stack_config())),
    }
    return RunBag(
        path, intrinsics=scn.kinect.intrinsics, mount=scn.kinect.mount, walls=np.asarray(building.vectormap.segments),
        frame_dt=1.0 / scn.kinect.rate_hz, run_info=info, depth_encoding=depth_encoding,
    )


def map_from_odom(estimate: np.ndarray, odom: np.ndarray) -> np.ndarray:
    """The map -> odom transform that puts the odometry's pose on the estimate."""
    return compose_pose(np.asarray(estimate, dtype=np.float64), relative_pose(np.asarray(odom, dtype=np.float64), np.zeros(3)))


def write_drive_bag(log, path: str | Path, walls: np.ndarray) -> int:
    """A recorded drive (:class:`sim.experiments.drives.DriveLog`, the localization
    comparison's) as a bag: its depth frames (``16UC1``, the millimetres it stores),
    the noise-free odometry it recorded (a replay adds none), the truth and the map's
    ``walls``; returns the frames written."""
    t = np.asarray(log.t, dtype=np.float64)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0 / 30.0
    info = {
        "drive": log.meta, "map": log.map_name, "start_pose": [float(v) for v in log.poses[0]], "start_known": True,
        "frame_rate_hz": 1.0 / dt, "odometry": "noise-free (the recording's; the comparison's replays add 20 %)",
    }
    bag = RunBag(path, intrinsics=log.intrinsics, mount=log.mount, walls=walls, frame_dt=dt, run_info=info, depth_encoding="16UC1")
    try:
        for k in range(len(t)):
            depth = np.asarray(log.depth_mm[k], dtype=np.float32) * np.float32(0.001)
            bag.sensor_frame(float(t[k]), depth, None if k == 0 else log.increments[k], log.poses[k])
    finally:
        bag.close()
    return len(t)
