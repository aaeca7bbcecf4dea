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
  fan, theta* (Eq. 5), the carrot direction and the robot's safety radius;
  ``world/robot/avoidance/near_field`` the sight lines where the camera fails to see the
  near floor (something closer than its minimum range, autonomy/perception/nearfield.py).
- ``metrics/...`` scalars over time (speed, per-stage CPU ms, ...).
- ``world/plane_map/<name>/{patches,leaves,normals}`` an octree plane map (mapping
  experiments): plane patches as one mesh coloured by normal direction, the occupied
  leaves as wire boxes, and each plane's normal at its centre;
  ``world/detections/<name>/{points,boundaries}`` one frame's detected planes.

Heavy items (depth images, trajectories, people) are logged every ``every``-th frame;
depth goes in as uint16 millimetres at half resolution (with a matching pinhole), which
keeps a 150 s demo near 50 MB. Trajectories are cut into strips of at most
``TRAIL_CHUNK`` points (``world/trajectory/truth/<k>``), so a multi-kilometre run logs
each point a bounded number of times instead of re-logging the whole path.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from autonomy.common.errors import InputError
from autonomy.maps.navgraph import NavGraph
from autonomy.maps.vectormap import VectorMap
from autonomy.perception.camera import CameraIntrinsics, CameraMount
from sim.viz.viewer import viewer_executable

TRUTH_COLOR = (40, 170, 60)
ESTIMATE_COLOR = (230, 90, 30)
TRAIL_CHUNK = 600
"""Points per trajectory strip; a full strip is frozen and a new one started."""


def label_colors(labels: np.ndarray) -> np.ndarray:
    """A fixed, well-spread RGB colour per non-negative label (golden-angle hue); grey for -1."""
    ids = np.asarray(labels, dtype=np.int64)
    hue = (ids * 0.618033988749895) % 1.0
    colors = (255 * np.column_stack([0.5 + 0.5 * np.cos(2 * np.pi * (hue + k / 3)) for k in range(3)])).astype(np.uint8)
    colors[ids < 0] = 140
    return colors


class _Trail:
    """A growing path logged as a chain of bounded line strips under ``path/<k>``."""

    def __init__(self, path: str, color: tuple[int, int, int], z: float) -> None:
        self.path, self.color, self.z = path, color, z
        self.points: list[tuple[float, float]] = []
        self.chunk = 0

    def append(self, x: float, y: float) -> None:
        self.points.append((float(x), float(y)))

    def log(self, rec: rr.RecordingStream) -> None:
        if len(self.points) < 2:
            return
        strip = np.column_stack([np.asarray(self.points), np.full(len(self.points), self.z)])
        rec.log(f"{self.path}/{self.chunk}", rr.LineStrips3D([strip], colors=self.color, radii=0.03))
        if len(self.points) >= TRAIL_CHUNK:
            self.points = self.points[-1:]
            self.chunk += 1

    def reset(self, rec: rr.RecordingStream | None = None) -> None:
        """Forget the path (a new episode); clears the logged strips when given the stream."""
        if rec is not None:
            rec.log(self.path, rr.Clear(recursive=True))
        self.points.clear()
        self.chunk = 0


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
            if self.path.is_dir():
                raise InputError(f"{self.path}: expected a file name for the rerun recording, got a directory")
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self.rec.save(str(self.path))
            except (OSError, RuntimeError) as exc:
                raise InputError(f"{self.path}: cannot write the rerun recording: {getattr(exc, 'strerror', None) or exc}") from None
        elif spawn:
            rr.spawn(executable_path=viewer_executable(), recording=self.rec)
        else:
            self._memory = self.rec.memory_recording()
        self.rec.send_blueprint(default_blueprint())
        self._truth = _Trail("world/trajectory/truth", TRUTH_COLOR, 0.03)
        self._estimate = _Trail("world/trajectory/estimate", ESTIMATE_COLOR, 0.05)

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
        self._truth.append(pose[0], pose[1])
        if self.heavy(frame):
            self._truth.log(self.rec)

    def reset_trajectory(self) -> None:
        """Start a new driven path and estimate (a new episode); the old strips are cleared."""
        self._truth.reset(self.rec)
        self._estimate.reset(self.rec)

    def log_depth(self, depth: np.ndarray) -> None:
        """Depth as uint16 millimetres (the Kinect's own format), every k-th pixel."""
        k = self.depth_downsample
        mm = np.round(np.asarray(depth)[k // 2 :: k, k // 2 :: k] * 1000.0).astype(np.uint16)
        self.rec.log("world/robot/camera/depth", rr.DepthImage(mm, meter=1000.0, depth_range=[0.0, 4500.0]))

    def log_fspf(self, res, max_arrows: int = 200) -> None:
        """FSPF output in the robot frame: plane points coloured by local plane, outliers, normals."""
        if len(res.points):
            colors = label_colors(res.plane_ids)
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

    def log_estimate(self, frame: int, pose: np.ndarray) -> None:
        """The localization estimate (transform every frame, path strip on heavy frames)."""
        self.rec.log("world/estimate", rr.Transform3D(translation=[pose[0], pose[1], 0.0], quaternion=_yaw_quat_xyzw(pose[2])))
        self._estimate.append(pose[0], pose[1])
        if self.heavy(frame):
            self._estimate.log(self.rec)

    def log_localization(self, before: np.ndarray, after: np.ndarray, weights: np.ndarray | None = None) -> None:
        """The CGR particles before and after refinement (pose arrows, Alg. 1 lines 3 and 4-6).

        With ``weights`` the refined particles are coloured by weight relative to the
        largest (dark: low, bright orange: high).
        """
        for name, parts, color in (("first_stage", before, (150, 150, 255)), ("refined", after, (255, 140, 0))):
            if len(parts):
                o = np.column_stack([parts[:, :2], np.full(len(parts), 0.1)])
                v = np.column_stack([0.3 * np.cos(parts[:, 2]), 0.3 * np.sin(parts[:, 2]), np.zeros(len(parts))])
                c = color
                if name == "refined" and weights is not None and len(weights) == len(parts):
                    w = np.asarray(weights, dtype=np.float64)
                    t = w / w.max() if w.max() > 0 else np.ones_like(w)
                    c = np.column_stack([80 + 175 * t, 40 + 100 * t, np.full(len(t), 20)]).astype(np.uint8)
                self.rec.log(f"world/particles/{name}", rr.Arrows3D(origins=o, vectors=v, colors=c))

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

    def log_near_field(self, lines: np.ndarray) -> None:
        """The near field's blocked sight lines (robot frame, autonomy/perception/nearfield.py): where
        the camera fails to see the floor right in front, something closer than its range."""
        seg = np.asarray(lines, dtype=np.float32).reshape(-1, 4)
        strips = np.zeros((len(seg), 2, 3), dtype=np.float32)
        strips[:, 0, :2], strips[:, 1, :2] = seg[:, :2], seg[:, 2:]
        strips[:, :, 2] = 0.05
        self.rec.log("world/robot/avoidance/near_field", rr.LineStrips3D(strips, colors=(255, 60, 200), radii=0.008))

    def log_people(self, xyh: np.ndarray, radius_m: float = 0.22, height_m: float = 1.75) -> None:
        if len(xyh):
            n = len(xyh)
            centers = np.column_stack([xyh[:, :2], np.full(n, height_m / 2)])
            self.rec.log(
                "world/people",
                rr.Boxes3D(centers=centers, half_sizes=np.tile([radius_m, radius_m, height_m / 2], (n, 1)), colors=(210, 110, 90), fill_mode="solid"),
            )

    # -- plane maps (mapping experiments) ------------------------------------------------
    def log_plane_map(self, tree, name: str, leaves: bool = True, normals: bool = True) -> None:
        """An octree plane map (PlaneMap, Section II): patches, occupied leaves, normals.

        ``tree`` is an :class:`autonomy.planes.PlaneOctree` (its ``patches()`` and
        ``leaf_boxes()``); logged at the current time, so a map growing over a run can be
        scrubbed through.
        """
        base = f"world/plane_map/{name}"
        pa = tree.patches()
        if len(pa.triangles):
            vn = np.zeros((len(pa.vertices), 3), dtype=np.float32)
            for k in range(3):
                vn[pa.triangles[:, k]] = pa.normals[pa.triangle_patch]
            self.rec.log(
                f"{base}/patches",
                rr.Mesh3D(vertex_positions=pa.vertices, triangle_indices=pa.triangles, vertex_colors=pa.vertex_colors, vertex_normals=vn),
            )
        else:
            self.rec.log(f"{base}/patches", rr.Clear(recursive=False))
        if leaves:
            c, h = tree.leaf_boxes()
            if len(c):
                self.rec.log(f"{base}/leaves", rr.Boxes3D(centers=c, half_sizes=h, colors=(150, 150, 150, 80), radii=0.004))
        if normals and len(pa.centres):
            self.rec.log(f"{base}/normals", rr.Arrows3D(origins=pa.centres, vectors=0.3 * pa.normals, colors=pa.colors))

    def log_detection(
        self, name: str, points: np.ndarray, labels: np.ndarray, planes, origin: np.ndarray | None = None, max_points: int = 20000
    ) -> None:
        """One frame's detected planes: points coloured by plane (grey: none) and boundaries.

        ``points`` (N, 3) and the planes' hulls are in a sensor-centred frame with the
        world's axes (``autonomy.planes.detection_frame``); ``origin`` is the sensor's
        position in the world. At most ``max_points`` points are logged (evenly strided).
        """
        base = f"world/detections/{name}"
        off = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64)
        pts = np.asarray(points, dtype=np.float32)
        lab = np.asarray(labels)
        step = max(1, len(pts) // max_points)
        if len(pts):
            self.rec.log(f"{base}/points", rr.Points3D(pts[::step] + off.astype(np.float32), colors=label_colors(lab[::step]), radii=0.01))
        hulls = [np.vstack([p.hull, p.hull[:1]]) + off for p in planes if len(p.hull) >= 3]
        if hulls:
            colors = label_colors(np.array([k for k, p in enumerate(planes) if len(p.hull) >= 3]))
            self.rec.log(f"{base}/boundaries", rr.LineStrips3D(hulls, colors=colors, radii=0.01))
        else:
            self.rec.log(f"{base}/boundaries", rr.Clear(recursive=False))

    def log_frame_transform(self, path: str, t: np.ndarray) -> None:
        """A 4 x 4 rigid transform (parent from child) at ``path``."""
        t = np.asarray(t, dtype=np.float64)
        self.rec.log(path, rr.Transform3D(translation=t[:3, 3], quaternion=_rot_to_quat_xyzw(t[:3, :3])))

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
