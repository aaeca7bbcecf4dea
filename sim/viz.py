"""Rerun recordings of runs: the only module of depthnav that imports ``rerun``.

Entity layout (timelines ``sim_time`` in seconds and ``frame``):

- ``world/map/walls`` the vector map as 3D boxes (static); ``world/map/lines`` its lines
  on the floor; ``world/map/navgraph`` the navigation graph.
- ``world/furniture`` unmapped furniture (static boxes); ``world/people`` people (boxes).
- ``world/robot`` ground-truth pose (Transform3D) with ``world/robot/base``;
  ``world/robot/camera`` the Kinect (mount transform + Pinhole, optical frame RDF) and
  ``world/robot/camera/depth`` the depth image under it, so the viewer back-projects it.
- ``world/robot/fspf/{plane_points,normals,outliers}`` FSPF output (robot frame).
- ``world/trajectory/truth`` the driven path, ``world/trajectory/estimate`` the CGR
  estimate, ``world/particles/{first_stage,refined}`` the particles; ``world/waypoints``.
- ``world/localization/{scene_lines,correspondences,observed}`` the analytic ray cast's
  scene lines at the estimate and each observed point's line (world frame).
- ``world/robot/avoidance/{fan,chosen,desired,margin}`` open path lengths (Eq. 4) as a
  fan, theta* (Eq. 5), the carrot direction and the robot's safety radius.
- ``metrics/...`` scalars over time (speed, per-stage CPU ms, ...).

Heavy items (depth images, trajectories, people) are logged every ``every``-th frame;
depth goes in as uint16 millimetres at half resolution (with a matching pinhole), which
keeps a 150 s demo near 50 MB.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from autonomy.camera import CameraIntrinsics, CameraMount
from autonomy.vectormap import NavGraph, VectorMap

TRUTH_COLOR = (40, 170, 60)
ESTIMATE_COLOR = (230, 90, 30)


def _yaw_quat_xyzw(yaw: float) -> list[float]:
    return [0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]


def _rot_to_quat_xyzw(r: np.ndarray) -> list[float]:
    """Rotation matrix -> rerun quaternion (xyzw)."""
    w = math.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = math.copysign(math.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2, r[1, 0] - r[0, 1])
    return [x, y, z, w]


def default_blueprint() -> rrb.Blueprint:
    """3D world view, the depth image, and time series of the metrics."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="World", origin="world"),
            rrb.Vertical(
                rrb.Spatial2DView(name="Depth", origin="world/robot/camera"),
                rrb.TimeSeriesView(name="Metrics", origin="metrics"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


class Recorder:
    """Logs a run to a rerun recording: an .rrd file, a spawned viewer, or memory."""

    def __init__(
        self,
        path: str | Path | None = None,
        *,
        spawn: bool = False,
        every: int = 15,
        depth_downsample: int = 2,
        recording_id: str | None = None,
        application_id: str = "depthnav",
    ) -> None:
        self.every = max(1, int(every))
        self.depth_downsample = max(1, int(depth_downsample))
        self.rec = rr.RecordingStream(application_id, recording_id=recording_id)
        self.path = Path(path) if path else None
        self._memory = None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.rec.save(str(self.path))
        elif spawn:
            self.rec.spawn()
        else:
            self._memory = self.rec.memory_recording()
        self.rec.send_blueprint(default_blueprint())
        self._truth: list[tuple[float, float]] = []

    # -- static content -------------------------------------------------------------
    def log_map(self, vm: VectorMap, graph: NavGraph | None = None, wall_height_m: float = 2.5) -> None:
        seg = np.asarray(vm.segments)
        strips = np.zeros((len(seg), 2, 3), dtype=np.float32)
        strips[:, 0, :2] = seg[:, :2]
        strips[:, 1, :2] = seg[:, 2:]
        self.rec.log("world/map/lines", rr.LineStrips3D(strips, colors=(30, 60, 200), radii=0.02), static=True)
        d = seg[:, 2:] - seg[:, :2]
        yaw = np.arctan2(d[:, 1], d[:, 0])
        centers = np.column_stack([(seg[:, :2] + seg[:, 2:]) / 2, np.full(len(seg), wall_height_m / 2)])
        half = np.column_stack([np.hypot(d[:, 0], d[:, 1]) / 2, np.full(len(seg), 0.01), np.full(len(seg), wall_height_m / 2)])
        quats = np.column_stack([np.zeros(len(seg)), np.zeros(len(seg)), np.sin(yaw / 2), np.cos(yaw / 2)])
        self.rec.log(
            "world/map/walls",
            rr.Boxes3D(centers=centers, half_sizes=half, quaternions=quats, colors=(200, 200, 190, 90), fill_mode="solid"),
            static=True,
        )
        if graph is not None and len(graph.nodes):
            xy = graph.node_xy()
            pts = np.column_stack([xy, np.full(len(xy), 0.02)])
            self.rec.log("world/map/navgraph/nodes", rr.Points3D(pts, radii=0.06, colors=(150, 150, 150)), static=True)
            if graph.edges:
                e = np.array([[graph.index_of(x.s0_id), graph.index_of(x.s1_id)] for x in graph.edges])
                self.rec.log(
                    "world/map/navgraph/edges",
                    rr.LineStrips3D(pts[e], radii=0.015, colors=(170, 170, 170)),
                    static=True,
                )

    def log_furniture(self, boxes: list[tuple[np.ndarray, np.ndarray, float]]) -> None:
        """Static boxes (centre xyz, half sizes, yaw) of unmapped furniture."""
        if not boxes:
            return
        self.rec.log(
            "world/furniture",
            rr.Boxes3D(
                centers=[b[0] for b in boxes],
                half_sizes=[b[1] for b in boxes],
                quaternions=[_yaw_quat_xyzw(b[2]) for b in boxes],
                colors=(150, 110, 70),
                fill_mode="solid",
            ),
            static=True,
        )

    def log_camera_model(self, intr: CameraIntrinsics, mount: CameraMount) -> None:
        """The Kinect's mount transform and pinhole (at the logged depth resolution)."""
        k = self.depth_downsample
        intr = intr.scaled(intr.width // k, intr.height // k)
        self.rec.log(
            "world/robot/camera",
            rr.Transform3D(translation=mount.translation(), quaternion=_rot_to_quat_xyzw(mount.rotation())),
            static=True,
        )
        self.rec.log(
            "world/robot/camera",
            rr.Pinhole(
                focal_length=[intr.fx, intr.fy],
                principal_point=[intr.cx + 0.5, intr.cy + 0.5],
                width=intr.width,
                height=intr.height,
                camera_xyz=rr.ViewCoordinates.RDF,
                image_plane_distance=0.4,
            ),
            static=True,
        )

    def log_robot_shape(self, radius_m: float, height_m: float) -> None:
        self.rec.log(
            "world/robot/base",
            rr.Boxes3D(half_sizes=[[radius_m, radius_m, height_m / 2]], centers=[[0, 0, height_m / 2]], colors=(60, 90, 200, 120)),
            static=True,
        )

    def log_waypoints(self, xy: np.ndarray, static: bool = True) -> None:
        if len(xy):
            pts = np.column_stack([xy, np.full(len(xy), 0.05)])
            self.rec.log("world/waypoints", rr.Points3D(pts, radii=0.15, colors=(220, 40, 160)), static=static)

    # -- per frame ---------------------------------------------------------------------
    def set_time(self, frame: int, sim_time_s: float) -> None:
        self.rec.set_time("frame", sequence=frame)
        self.rec.set_time("sim_time", duration=sim_time_s)

    def heavy(self, frame: int) -> bool:
        """Whether heavy items are logged this frame."""
        return frame % self.every == 0

    def log_pose(self, frame: int, pose: np.ndarray) -> None:
        self.rec.log("world/robot", rr.Transform3D(translation=[pose[0], pose[1], 0.0], quaternion=_yaw_quat_xyzw(pose[2])))
        self._truth.append((float(pose[0]), float(pose[1])))
        if self.heavy(frame) and len(self._truth) > 1:
            strip = np.column_stack([np.asarray(self._truth), np.full(len(self._truth), 0.03)])
            self.rec.log("world/trajectory/truth", rr.LineStrips3D([strip], colors=TRUTH_COLOR, radii=0.03))

    def reset_trajectory(self) -> None:
        """Start a new driven-path strip (a new episode)."""
        self._truth.clear()

    def log_depth(self, depth: np.ndarray) -> None:
        """Depth as uint16 millimetres (the Kinect's own format), every k-th pixel."""
        k = self.depth_downsample
        mm = np.round(np.asarray(depth)[k // 2 :: k, k // 2 :: k] * 1000.0).astype(np.uint16)
        self.rec.log("world/robot/camera/depth", rr.DepthImage(mm, meter=1000.0, depth_range=[0.0, 4500.0]))

    def log_fspf(self, res, max_arrows: int = 200) -> None:
        """FSPF output in the robot frame: plane points coloured by local plane, outliers, normals."""
        if len(res.points):
            ids = res.plane_ids.astype(np.int64)
            # A fixed, well-spread colour per local plane (golden-angle hue).
            hue = (ids * 0.618033988749895) % 1.0
            colors = (255 * np.column_stack([0.5 + 0.5 * np.cos(2 * np.pi * (hue + k / 3)) for k in range(3)])).astype(np.uint8)
            self.rec.log("world/robot/fspf/plane_points", rr.Points3D(res.points, colors=colors, radii=0.015))
            step = max(1, len(res.points) // max_arrows)
            self.rec.log(
                "world/robot/fspf/normals",
                rr.Arrows3D(origins=res.points[::step], vectors=0.15 * res.normals[::step], colors=(240, 200, 40)),
            )
        else:
            self.rec.log("world/robot/fspf/plane_points", rr.Clear(recursive=False))
        if len(res.outliers):
            self.rec.log("world/robot/fspf/outliers", rr.Points3D(res.outliers, colors=(230, 60, 60), radii=0.012))
        else:
            self.rec.log("world/robot/fspf/outliers", rr.Clear(recursive=False))

    def log_localization(self, estimates: list[np.ndarray], before: np.ndarray, after: np.ndarray) -> None:
        """Estimated trajectory, and the CGR particles before and after refinement (arrows)."""
        if len(estimates) > 1:
            e = np.asarray(estimates)
            strip = np.column_stack([e[:, :2], np.full(len(e), 0.05)])
            self.rec.log("world/trajectory/estimate", rr.LineStrips3D([strip], colors=ESTIMATE_COLOR, radii=0.03))
            p = e[-1]
            self.rec.log("world/estimate", rr.Transform3D(translation=[p[0], p[1], 0.0], quaternion=_yaw_quat_xyzw(p[2])))
        for name, parts, color in (("first_stage", before, (150, 150, 255)), ("refined", after, (255, 140, 0))):
            if len(parts):
                o = np.column_stack([parts[:, :2], np.full(len(parts), 0.1)])
                v = np.column_stack([0.3 * np.cos(parts[:, 2]), 0.3 * np.sin(parts[:, 2]), np.zeros(len(parts))])
                self.rec.log(f"world/particles/{name}", rr.Arrows3D(origins=o, vectors=v, colors=color))

    def log_scene(self, lines: np.ndarray, pose: np.ndarray, points: np.ndarray, line_idx: np.ndarray) -> None:
        """The analytic ray cast's scene lines at the estimate, and point -> line correspondences.

        ``points`` are the 2D observations in the robot frame, ``line_idx`` the line each
        corresponds to at ``pose`` (-1: none); a correspondence is drawn from the point
        (placed with the estimate) to its closest point on the line.
        """
        lines = np.asarray(lines, dtype=np.float64).reshape(-1, 4)
        z = 0.08
        if len(lines):
            strips = np.zeros((len(lines), 2, 3), dtype=np.float32)
            strips[:, 0, :2], strips[:, 1, :2], strips[:, :, 2] = lines[:, :2], lines[:, 2:], z
            self.rec.log("world/localization/scene_lines", rr.LineStrips3D(strips, colors=(0, 200, 220), radii=0.025))
        else:
            self.rec.log("world/localization/scene_lines", rr.Clear(recursive=False))
        keep = np.asarray(line_idx) >= 0
        if not keep.any():
            self.rec.log("world/localization/correspondences", rr.Clear(recursive=False))
            return
        c, s_ = math.cos(pose[2]), math.sin(pose[2])
        pts = np.asarray(points, dtype=np.float64)[keep]
        wx = pose[0] + c * pts[:, 0] - s_ * pts[:, 1]
        wy = pose[1] + s_ * pts[:, 0] + c * pts[:, 1]
        seg = lines[np.asarray(line_idx)[keep]]
        d = seg[:, 2:] - seg[:, :2]
        l2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-12)
        t = np.clip(((wx - seg[:, 0]) * d[:, 0] + (wy - seg[:, 1]) * d[:, 1]) / l2, 0.0, 1.0)
        strips = np.zeros((len(pts), 2, 3), dtype=np.float32)
        strips[:, 0, 0], strips[:, 0, 1] = wx, wy
        strips[:, 1, 0], strips[:, 1, 1] = seg[:, 0] + t * d[:, 0], seg[:, 1] + t * d[:, 1]
        strips[:, :, 2] = z
        self.rec.log("world/localization/correspondences", rr.LineStrips3D(strips, colors=(255, 60, 200), radii=0.008))
        self.rec.log(
            "world/localization/observed",
            rr.Points3D(np.column_stack([wx, wy, np.full(len(wx), z)]), colors=(255, 60, 200), radii=0.02),
        )

    def log_avoidance(
        self, angles: np.ndarray, lengths: np.ndarray, theta_star: float, desired: float, radius_m: float, cap_m: float = 4.0
    ) -> None:
        """Open path lengths as a fan (robot frame), the chosen and desired directions, the margin."""
        a = np.asarray(angles, dtype=np.float64)
        d = np.minimum(np.asarray(lengths, dtype=np.float64), cap_m)
        if len(a):
            strips = np.zeros((len(a), 2, 3), dtype=np.float32)
            strips[:, 1, 0], strips[:, 1, 1] = d * np.cos(a), d * np.sin(a)
            strips[:, :, 2] = 0.12
            t = np.clip(d / cap_m, 0.0, 1.0)
            colors = np.column_stack([255 * (1 - t), 200 * t, np.full(len(t), 60)]).astype(np.uint8)
            self.rec.log("world/robot/avoidance/fan", rr.LineStrips3D(strips, colors=colors, radii=0.01))
        for name, th, color in (("chosen", theta_star, (40, 220, 40)), ("desired", desired, (220, 220, 40))):
            self.rec.log(
                f"world/robot/avoidance/{name}",
                rr.Arrows3D(origins=[[0, 0, 0.14]], vectors=[[math.cos(th), math.sin(th), 0.0]], colors=color, radii=0.02),
            )
        ring = np.linspace(0, 2 * np.pi, 37)
        self.rec.log(
            "world/robot/avoidance/margin",
            rr.LineStrips3D([np.column_stack([radius_m * np.cos(ring), radius_m * np.sin(ring), np.full(37, 0.12)])], colors=(120, 120, 255)),
        )

    def log_people(self, xyh: np.ndarray, radius_m: float = 0.22, height_m: float = 1.75) -> None:
        if len(xyh):
            n = len(xyh)
            centers = np.column_stack([xyh[:, :2], np.full(n, height_m / 2)])
            self.rec.log(
                "world/people",
                rr.Boxes3D(centers=centers, half_sizes=np.tile([radius_m, radius_m, height_m / 2], (n, 1)), colors=(210, 110, 90), fill_mode="solid"),
            )

    def log_scalars(self, values: dict[str, float]) -> None:
        for name, v in values.items():
            if v is not None and math.isfinite(v):
                self.rec.log(f"metrics/{name}", rr.Scalars([float(v)]))

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()

    def memory_bytes(self) -> bytes:
        """The recording so far, as .rrd bytes (memory recordings only)."""
        if self._memory is None:
            raise RuntimeError("not a memory recording")
        self.rec.flush()
        return bytes(self._memory.drain_as_bytes())
