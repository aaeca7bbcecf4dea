"""ROS 2 messages of a run, built from the simulator's and the robot stack's arrays.

The message types are ROS 2 Humble's (``rosbags``' type store: their definitions go into
the bag, so any reader decodes them without a ROS installation). Frames follow REP-105
and REP-103: ``map`` (the vector map's frame), ``odom`` (where the robot started, as
its wheel odometry integrates), ``base_link`` (the robot's centre on the floor, x
forward, y left, z up), ``camera_link`` (the optical centre, x forward) and
``camera_depth_optical_frame`` (z along the optical axis, x right, y down, as the
image), and ``laser`` (the simulated scan's origin: the optical centre dropped to the
floor, facing as the robot).
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
from rosbags.typesys import Stores, get_typestore

from autonomy.perception.camera import ROBOT_FROM_OPTICAL_LEVEL, CameraIntrinsics, CameraMount

#: Coordinate frames (REP-105).
MAP_FRAME = "map"
ODOM_FRAME = "odom"
BASE_FRAME = "base_link"
CAMERA_FRAME = "camera_link"
OPTICAL_FRAME = "camera_depth_optical_frame"
LASER_FRAME = "laser"

#: Depth encodings read and written: float metres (NaN or 0 invalid) and uint16 millimetres (0 invalid).
DEPTH_ENCODINGS = ("32FC1", "16UC1")

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
ODOMETRY = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"
POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE = "geometry_msgs/msg/PoseStamped"
CLOUD = "sensor_msgs/msg/PointCloud2"
SCAN = "sensor_msgs/msg/LaserScan"
MARKERS = "visualization_msgs/msg/MarkerArray"
TWIST = "geometry_msgs/msg/TwistStamped"
STRING = "std_msgs/msg/String"


@cache
def typestore():
    """The ROS 2 Humble type store (message classes, CDR serialization, definitions)."""
    return get_typestore(Stores.ROS2_HUMBLE)


def _t(name: str):
    return typestore().types[name]


def stamp_ns(t: float) -> int:
    """Seconds to integer nanoseconds (the bag's clock)."""
    return int(round(float(t) * 1e9))


def header(t_ns: int, frame_id: str):
    """A std_msgs/Header at ``t_ns`` in ``frame_id``."""
    Time, Header = _t("builtin_interfaces/msg/Time"), _t("std_msgs/msg/Header")
    return Header(stamp=Time(sec=int(t_ns // 1_000_000_000), nanosec=int(t_ns % 1_000_000_000)), frame_id=frame_id)


def header_ns(h) -> int:
    """A header's stamp in nanoseconds."""
    return int(h.stamp.sec) * 1_000_000_000 + int(h.stamp.nanosec)


def yaw_quaternion(yaw: float):
    """A geometry_msgs/Quaternion turning by ``yaw`` about z."""
    return _t("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw))


def quaternion_yaw(q) -> float:
    """The heading of a geometry_msgs/Quaternion (rotation about z; roll and pitch ignored)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def matrix_quaternion(r: np.ndarray):
    """A geometry_msgs/Quaternion from a 3 x 3 rotation matrix."""
    w = math.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2.0
    x = math.copysign(math.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2.0, r[2, 1] - r[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2.0, r[0, 2] - r[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2.0, r[1, 0] - r[0, 1])
    return _t("geometry_msgs/msg/Quaternion")(x=x, y=y, z=z, w=w)


def quaternion_matrix(q) -> np.ndarray:
    """The 3 x 3 rotation matrix of a (normalised) geometry_msgs/Quaternion."""
    n = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    if not n > 0:
        return np.eye(3)
    x, y, z, w = q.x / n, q.y / n, q.z / n, q.w / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def planar_pose(pose: np.ndarray):
    """A geometry_msgs/Pose from (x, y, theta) on the floor."""
    Point, Pose = _t("geometry_msgs/msg/Point"), _t("geometry_msgs/msg/Pose")
    return Pose(position=Point(x=float(pose[0]), y=float(pose[1]), z=0.0), orientation=yaw_quaternion(float(pose[2])))


def planar_transform(t_ns: int, parent: str, child: str, pose: np.ndarray):
    """A geometry_msgs/TransformStamped placing ``child`` at (x, y, theta) in ``parent``."""
    V3, Tr, TS = _t("geometry_msgs/msg/Vector3"), _t("geometry_msgs/msg/Transform"), _t("geometry_msgs/msg/TransformStamped")
    tr = Tr(translation=V3(x=float(pose[0]), y=float(pose[1]), z=0.0), rotation=yaw_quaternion(float(pose[2])))
    return TS(header=header(t_ns, parent), child_frame_id=child, transform=tr)


def transform(t_ns: int, parent: str, child: str, rot: np.ndarray, trans: np.ndarray):
    """A geometry_msgs/TransformStamped from a rotation matrix and a translation."""
    V3, Tr, TS = _t("geometry_msgs/msg/Vector3"), _t("geometry_msgs/msg/Transform"), _t("geometry_msgs/msg/TransformStamped")
    tr = Tr(translation=V3(x=float(trans[0]), y=float(trans[1]), z=float(trans[2])), rotation=matrix_quaternion(rot))
    return TS(header=header(t_ns, parent), child_frame_id=child, transform=tr)


def tf_message(transforms: list):
    """A tf2_msgs/TFMessage."""
    return _t(TF)(transforms=transforms)


def mount_transforms(t_ns: int, mount: CameraMount) -> list:
    """The static transforms base_link -> camera_link -> camera_depth_optical_frame, and
    base_link -> laser, for a camera mount."""
    c, s = math.cos(mount.pitch_down_rad), math.sin(mount.pitch_down_rad)
    # camera_link: at the optical centre, pitched down about its y axis (x forward, z up).
    r_pitch = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return [
        transform(t_ns, BASE_FRAME, CAMERA_FRAME, r_pitch, mount.translation()),
        transform(t_ns, CAMERA_FRAME, OPTICAL_FRAME, ROBOT_FROM_OPTICAL_LEVEL, np.zeros(3)),
        transform(t_ns, BASE_FRAME, LASER_FRAME, np.eye(3), np.array([mount.forward_m, mount.lateral_m, 0.0])),
    ]


def depth_image(t_ns: int, depth: np.ndarray, encoding: str = "32FC1"):
    """A sensor_msgs/Image of a depth frame (float32 metres, 0 invalid) as ``32FC1``
    metres (exact) or ``16UC1`` millimetres (rounded; 0 stays invalid)."""
    h, w = depth.shape
    if encoding == "32FC1":
        data = np.ascontiguousarray(depth, dtype="<f4")
        step = 4 * w
    elif encoding == "16UC1":
        mm = np.rint(np.nan_to_num(depth, nan=0.0, posinf=0.0, neginf=0.0) * 1000.0)
        data = np.ascontiguousarray(np.clip(mm, 0, 65535), dtype="<u2")
        step = 2 * w
    else:
        raise ValueError(f"depth encoding {encoding!r}: expected one of {', '.join(DEPTH_ENCODINGS)}")
    return _t(IMAGE)(
        header=header(t_ns, OPTICAL_FRAME), height=h, width=w, encoding=encoding, is_bigendian=0, step=step,
        data=data.view(np.uint8).reshape(-1),
    )


def image_depth(msg, topic: str) -> np.ndarray:
    """A depth sensor_msgs/Image as float32 metres, 0 invalid (``32FC1`` NaN and
    infinities become 0). Raises ValueError naming ``topic`` on an encoding it cannot read."""
    enc = str(msg.encoding).upper()
    if enc not in DEPTH_ENCODINGS:
        raise ValueError(f"topic {topic}: depth image encoding {msg.encoding!r}; expected 32FC1 (metres) or 16UC1 (millimetres)")
    h, w = int(msg.height), int(msg.width)
    size = 4 if enc == "32FC1" else 2
    if int(msg.step) < w * size or len(msg.data) < int(msg.step) * h:
        raise ValueError(f"topic {topic}: depth image of {w} x {h} {enc} with step {msg.step} holds {len(msg.data)} bytes")
    order = ">" if msg.is_bigendian else "<"
    raw = np.asarray(msg.data, dtype=np.uint8)[: int(msg.step) * h].reshape(h, int(msg.step))[:, : w * size]
    if enc == "32FC1":
        d = np.ascontiguousarray(raw).view(order + "f4").astype(np.float32)
        d[~np.isfinite(d)] = 0.0
        return d
    return np.ascontiguousarray(raw).view(order + "u2").astype(np.float32) * np.float32(0.001)


def camera_info(t_ns: int, intr: CameraIntrinsics):
    """A sensor_msgs/CameraInfo of a pinhole camera without distortion."""
    k = np.array([intr.fx, 0.0, intr.cx, 0.0, intr.fy, intr.cy, 0.0, 0.0, 1.0])
    p = np.array([intr.fx, 0.0, intr.cx, 0.0, 0.0, intr.fy, intr.cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    roi = _t("sensor_msgs/msg/RegionOfInterest")(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return _t(CAMERA_INFO)(
        header=header(t_ns, OPTICAL_FRAME), height=intr.height, width=intr.width, distortion_model="plumb_bob",
        d=np.zeros(5), k=k, r=np.eye(3).reshape(-1), p=p, binning_x=0, binning_y=0, roi=roi,
    )


def _cov6(sxx: float, sxy: float, syy: float, stt: float) -> np.ndarray:
    c = np.zeros(36)
    c[0], c[1], c[6], c[7], c[35] = sxx, sxy, sxy, syy, stt
    # z, roll and pitch are not estimated: a large variance says so (REP-105 practice).
    c[14] = c[21] = c[28] = 1e6
    return c


def odometry(t_ns: int, pose: np.ndarray, velocity: np.ndarray):
    """A nav_msgs/Odometry: the integrated wheel odometry (odom -> base_link) and the
    base's velocity in base_link."""
    V3, Tw = _t("geometry_msgs/msg/Vector3"), _t("geometry_msgs/msg/Twist")
    PwC, TwC = _t("geometry_msgs/msg/PoseWithCovariance"), _t("geometry_msgs/msg/TwistWithCovariance")
    tw = Tw(linear=V3(x=float(velocity[0]), y=float(velocity[1]), z=0.0), angular=V3(x=0.0, y=0.0, z=float(velocity[2])))
    return _t(ODOMETRY)(
        header=header(t_ns, ODOM_FRAME), child_frame_id=BASE_FRAME,
        pose=PwC(pose=planar_pose(pose), covariance=np.zeros(36)), twist=TwC(twist=tw, covariance=np.zeros(36)),
    )


def pose_with_covariance(t_ns: int, pose: np.ndarray, cov_xy: np.ndarray, std_theta: float):
    """A geometry_msgs/PoseWithCovarianceStamped in ``map`` (the CGR estimate)."""
    PwC = _t("geometry_msgs/msg/PoseWithCovariance")
    c = _cov6(float(cov_xy[0, 0]), float(cov_xy[0, 1]), float(cov_xy[1, 1]), float(std_theta) ** 2)
    return _t(POSE_COV)(header=header(t_ns, MAP_FRAME), pose=PwC(pose=planar_pose(pose), covariance=c))


def pose_stamped(t_ns: int, pose: np.ndarray, frame: str = MAP_FRAME):
    """A geometry_msgs/PoseStamped (the ground truth, in ``map``)."""
    return _t(POSE)(header=header(t_ns, frame), pose=planar_pose(pose))


def point_cloud(t_ns: int, points: np.ndarray, frame: str = BASE_FRAME):
    """A sensor_msgs/PointCloud2 of (n, 3) points, x y z float32."""
    PF = _t("sensor_msgs/msg/PointField")
    fields = [PF(name=n, offset=4 * i, datatype=PF.FLOAT32, count=1) for i, n in enumerate("xyz")]
    pts = np.ascontiguousarray(np.asarray(points, dtype="<f4").reshape(-1, 3))
    return _t(CLOUD)(
        header=header(t_ns, frame), height=1, width=len(pts), fields=fields, is_bigendian=False, point_step=12,
        row_step=12 * len(pts), data=pts.view(np.uint8).reshape(-1), is_dense=True,
    )


def cloud_points(msg) -> np.ndarray:
    """The (n, 3) x y z of a float32 sensor_msgs/PointCloud2."""
    off = {f.name: int(f.offset) for f in msg.fields}
    n = int(msg.width) * int(msg.height)
    raw = np.asarray(msg.data, dtype=np.uint8).reshape(n, int(msg.point_step))
    order = ">" if msg.is_bigendian else "<"
    return np.stack([np.ascontiguousarray(raw[:, off[k]: off[k] + 4]).view(order + "f4")[:, 0] for k in "xyz"], axis=1)


def laser_scan(t_ns: int, ranges: np.ndarray, angle_min: float, increment: float, range_min: float, range_max: float, scan_time: float):
    """A sensor_msgs/LaserScan in ``laser`` (0 in ``ranges``: no return, written as inf per REP-117)."""
    r = np.asarray(ranges, dtype=np.float32).copy()
    r[~(r > 0)] = np.inf
    return _t(SCAN)(
        header=header(t_ns, LASER_FRAME), angle_min=float(angle_min), angle_max=float(angle_min + increment * (len(r) - 1)),
        angle_increment=float(increment), time_increment=0.0, scan_time=float(scan_time), range_min=float(range_min),
        range_max=float(range_max), ranges=r, intensities=np.zeros(0, dtype=np.float32),
    )


def wall_markers(t_ns: int, segments: np.ndarray, height_m: float = 2.0):
    """A visualization_msgs/MarkerArray of the vector map: one LINE_LIST of its walls on
    the floor and one of their tops."""
    M, P, C = _t("visualization_msgs/msg/Marker"), _t("geometry_msgs/msg/Point"), _t("std_msgs/msg/ColorRGBA")
    V3, D = _t("geometry_msgs/msg/Vector3"), _t("builtin_interfaces/msg/Duration")
    tex = _t("sensor_msgs/msg/CompressedImage")(header=header(t_ns, MAP_FRAME), format="", data=np.zeros(0, np.uint8))
    mesh = _t("visualization_msgs/msg/MeshFile")(filename="", data=np.zeros(0, np.uint8))
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    markers = []
    for i, (z, ns) in enumerate(((0.0, "walls"), (height_m, "wall_tops"))):
        pts = [P(x=float(s[k]), y=float(s[k + 1]), z=z) for s in seg for k in (0, 2)]
        markers.append(M(
            header=header(t_ns, MAP_FRAME), ns=ns, id=i, type=M.LINE_LIST, action=M.ADD, pose=planar_pose(np.zeros(3)),
            scale=V3(x=0.03, y=0.0, z=0.0), color=C(r=0.2, g=0.2, b=0.2, a=1.0), lifetime=D(sec=0, nanosec=0),
            frame_locked=False, points=pts, colors=[], texture_resource="", texture=tex, uv_coordinates=[], text="",
            mesh_resource="", mesh_file=mesh, mesh_use_embedded_materials=False,
        ))
    return _t(MARKERS)(markers=markers)


def twist_stamped(t_ns: int, velocity: np.ndarray):
    """A geometry_msgs/TwistStamped in base_link: the command (vx, vy, omega)."""
    V3, Tw = _t("geometry_msgs/msg/Vector3"), _t("geometry_msgs/msg/Twist")
    tw = Tw(linear=V3(x=float(velocity[0]), y=float(velocity[1]), z=0.0), angular=V3(x=0.0, y=0.0, z=float(velocity[2])))
    return _t(TWIST)(header=header(t_ns, BASE_FRAME), twist=tw)


def string(text: str):
    """A std_msgs/String."""
    return _t(STRING)(data=text)
