"""Reading a robot's bag for the robot stack: depth frames, odometry, the camera.

:func:`open_bag` reads rosbag2 bags (MCAP or SQLite storage, a directory or a lone
``.mcap`` file) and ROS 1 ``.bag`` files through ``rosbags``, checks what the stack
needs, and returns a :class:`BagSource`: the camera's intrinsics (``CameraInfo``) and
mount (``/tf_static``, or ``/tf``), the odometry (``nav_msgs/Odometry`` poses), the ground
truth and the run's settings when the bag has them (a depthnav bag), and
:meth:`BagSource.frames`, the depth frames in order with the odometry at each frame's
stamp. Every problem a user can cause (a missing topic, another message type, an
encoding the stack cannot read, stamps out of order, a camera model that does not match
its images) is one line naming the topic.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError

from autonomy.common.errors import InputError
from autonomy.common.geometry import wrap_angle
from autonomy.perception.camera import ROBOT_FROM_OPTICAL_LEVEL, CameraIntrinsics, CameraMount
from sim.rosbag import messages as m
from sim.rosbag.run_bag import TOPICS

#: A gap between depth frames longer than this many of the usual interval holds frames
#: the camera dropped: the stack is stepped once per missing frame without an image.
DROPPED_GAP = 1.5

#: The camera's transform is looked for in /tf_static, then in this many /tf messages.
TF_MESSAGES = 300

#: The camera mount's roll and yaw must be below this: the stack models a camera pitched
#: down about the robot's y axis.
MOUNT_TOLERANCE_RAD = math.radians(0.5)


@dataclass(frozen=True)
class BagTopics:
    """The topics and frames a replay reads (defaults: a depthnav bag's, REP-105's)."""

    depth: str = TOPICS.depth
    camera_info: str = TOPICS.camera_info
    odom: str = TOPICS.odom
    truth: str = TOPICS.truth
    tf_static: str = TOPICS.tf_static
    tf: str = TOPICS.tf
    run: str = TOPICS.run
    walls: str = TOPICS.map
    estimate: str = TOPICS.estimate
    base_frame: str = m.BASE_FRAME


DEFAULT_TOPICS = BagTopics()


@dataclass(frozen=True)
class BagFrame:
    """One camera frame: its stamp, its depth (float32 metres, 0 invalid; None: a frame
    the camera dropped) and the odometry pose at that stamp (odom frame)."""

    t: float
    depth: np.ndarray | None
    odom: np.ndarray


def _field(msg, *names):
    for n in names:
        if hasattr(msg, n):
            return getattr(msg, n)
    raise AttributeError(names[0])


class BagSource:
    """What a bag gives the robot stack (see the module docstring)."""

    def __init__(self, path: str | Path, topics: BagTopics = DEFAULT_TOPICS, mount: CameraMount | None = None) -> None:
        self.path = Path(path)
        self.topics = topics
        if not self.path.exists():
            raise InputError(f"{self.path}: no such bag (a .mcap or .db3 file, a rosbag2 directory or a ROS 1 .bag)")
        try:
            self.reader = AnyReader([self.path])
            self.reader.open()
        except (AnyReaderError, OSError, ValueError, KeyError) as exc:
            raise InputError(f"{self.path}: not a readable bag ({exc})") from None
        self._conns = {}
        for c in self.reader.connections:
            self._conns.setdefault(c.topic, []).append(c)
        self._check_type(topics.depth, m.IMAGE, "--depth-topic")
        self._check_type(topics.odom, m.ODOMETRY, "--odom-topic")
        self._check_type(topics.camera_info, m.CAMERA_INFO, "--camera-info-topic")
        if topics.truth in self._conns:
            self._check_type(topics.truth, m.POSE, "--truth-topic")
        self._scan()
        self.run_info = self._run_info()
        self.intrinsics, self.optical_frame, self._size = self._camera()
        self.mount = mount if mount is not None else self._mount()
        self.odom_t, self.odom_poses = self._odometry()
        self.truth_t, self.truth_poses = self._truth()
        self.depth_stamps = self._depth_stamps()

    def close(self) -> None:
        self.reader.close()

    # -- checks ---------------------------------------------------------------------------
    def _topic_list(self) -> str:
        return ", ".join(sorted(self._conns)) or "none"

    def _check_type(self, topic: str, msgtype: str, option: str) -> None:
        conns = self._conns.get(topic)
        if not conns:
            raise InputError(f"{self.path}: no topic {topic} (the bag has: {self._topic_list()}); name yours with {option}")
        for c in conns:
            if c.msgtype != msgtype:
                raise InputError(f"{self.path}: topic {topic} carries {c.msgtype}; expected {msgtype}")

    def messages(self, topic: str) -> list[object]:
        """The decoded messages of one of the topics read when the bag was opened (every
        topic of :class:`BagTopics` but the images), in order; none if the bag lacks it."""
        return self._read.get(topic, [])

    def _scan(self) -> None:
        """One pass over the bag for everything but the images' pixels: a bag's chunks mix
        its topics, so each pass decompresses all of it (the images dominate)."""
        tp = self.topics
        small = [tp.camera_info, tp.odom, tp.truth, tp.tf_static, tp.tf, tp.run, tp.walls, tp.estimate]
        self._read: dict[str, list] = {t: [] for t in small}
        self._depth_headers: list[tuple[int, int, int, str]] = []
        # The extras of a depthnav bag are read only with the types it writes them as.
        extras = {tp.tf_static: m.TF, tp.tf: m.TF, tp.run: m.STRING, tp.walls: m.MARKERS, tp.estimate: m.POSE_COV}
        conns = [c for t in (*small, tp.depth) for c in self._conns.get(t, []) if extras.get(t, c.msgtype) == c.msgtype]
        for conn, t_log, raw in self.reader.messages(connections=conns):
            topic = conn.topic
            if topic in (tp.camera_info, tp.run, tp.walls) and self._read[topic]:
                continue  # the first is all the replay reads
            if topic == tp.tf and len(self._read[topic]) >= TF_MESSAGES:
                continue
            try:
                msg = self.reader.deserialize(raw, conn.msgtype)
            except Exception as exc:  # a corrupt message: named, in one line
                raise InputError(f"{self.path}: topic {topic}: a message at {t_log} ns does not decode as {conn.msgtype} ({exc})") from None
            if topic == tp.depth:
                self._depth_headers.append((m.header_ns(msg.header), int(msg.width), int(msg.height), str(msg.encoding)))
            else:
                self._read[topic].append(msg)

    def _messages(self, topic: str) -> Iterator[tuple[int, object]]:
        conns = self._conns.get(topic, [])
        if not conns:
            return
        for conn, t_log, raw in self.reader.messages(connections=conns):
            try:
                yield t_log, self.reader.deserialize(raw, conn.msgtype)
            except Exception as exc:  # a corrupt message: named, in one line
                raise InputError(f"{self.path}: topic {topic}: a message at {t_log} ns does not decode as {conn.msgtype} ({exc})") from None

    @staticmethod
    def _ordered(topic: str, stamps: list[int], path: Path) -> None:
        s = np.asarray(stamps, dtype=np.int64)
        bad = np.nonzero(np.diff(s) <= 0)[0]
        if len(bad):
            i = int(bad[0])
            raise InputError(
                f"{path}: topic {topic}: header stamps out of order at message {i + 1} "
                f"({s[i + 1] / 1e9:.6f} s after {s[i] / 1e9:.6f} s); the replay needs them strictly increasing"
            )

    # -- the parts --------------------------------------------------------------------------
    def _run_info(self) -> dict | None:
        for msg in self.messages(self.topics.run):
            try:
                info = json.loads(msg.data)
            except (ValueError, AttributeError):
                raise InputError(f"{self.path}: topic {self.topics.run}: not the JSON of a depthnav run") from None
            return info if isinstance(info, dict) else None
        return None

    def _camera(self) -> tuple[CameraIntrinsics, str, tuple[int, int]]:
        tp = self.topics.camera_info
        for msg in self.messages(tp):
            k = np.asarray(_field(msg, "k", "K"), dtype=np.float64).reshape(-1)
            d = np.asarray(_field(msg, "d", "D"), dtype=np.float64).reshape(-1)
            w, h = int(msg.width), int(msg.height)
            if len(k) != 9 or not (k[0] > 0 and k[4] > 0) or abs(k[1]) > 1e-9:
                raise InputError(f"{self.path}: topic {tp}: camera matrix K = {k.tolist()} is not a pinhole without skew")
            if np.any(np.abs(d) > 1e-9):
                raise InputError(
                    f"{self.path}: topic {tp}: distortion {msg.distortion_model} {d.tolist()}; the stack needs a rectified "
                    "depth image (rectify it first, e.g. with image_proc)"
                )
            intr = CameraIntrinsics(width=w, height=h, fx=float(k[0]), fy=float(k[4]), cx=float(k[2]), cy=float(k[5]))
            return intr, str(msg.header.frame_id), (w, h)
        raise InputError(f"{self.path}: topic {tp} has no message; the stack needs the depth camera's intrinsics")

    def _mount(self) -> CameraMount:
        """The base frame -> optical frame transform from /tf_static (or /tf), as a mount."""
        edges: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
        optical = self.optical_frame.lstrip("/")
        for topic in (self.topics.tf_static, self.topics.tf):
            if self.topics.base_frame in _ancestors(edges, optical):
                break
            for msg in self.messages(topic):
                for ts in msg.transforms:
                    child = str(ts.child_frame_id).lstrip("/")
                    if child not in edges:
                        tr = ts.transform
                        edges[child] = (
                            str(ts.header.frame_id).lstrip("/"), m.quaternion_matrix(tr.rotation),
                            np.array([tr.translation.x, tr.translation.y, tr.translation.z]),
                        )
                if self.topics.base_frame in _ancestors(edges, optical):
                    break
        base, frame = self.topics.base_frame, self.optical_frame.lstrip("/")
        rot, trans = np.eye(3), np.zeros(3)
        seen = set()
        while frame != base:
            if frame not in edges or frame in seen:
                raise InputError(
                    f"{self.path}: topics {self.topics.tf_static}, {self.topics.tf}: no transform from {base} to "
                    f"{self.optical_frame} (the depth image's frame); give the mount with --mount height,forward,lateral,pitch_deg"
                )
            seen.add(frame)
            parent, r, t = edges[frame]
            rot, trans = r @ rot, r @ trans + t
            frame = parent
        return mount_from_transform(rot, trans, f"{self.path}: camera mount ({base} -> {self.optical_frame})")

    def _odometry(self) -> tuple[np.ndarray, np.ndarray]:
        tp = self.topics.odom
        ts, poses = [], []
        for msg in self.messages(tp):
            p = msg.pose.pose
            ts.append(m.header_ns(msg.header))
            poses.append((p.position.x, p.position.y, m.quaternion_yaw(p.orientation)))
        if len(ts) < 2:
            raise InputError(f"{self.path}: topic {tp} has {len(ts)} message(s); the stack needs the odometry through the drive")
        self._ordered(tp, ts, self.path)
        return np.asarray(ts, dtype=np.int64), np.asarray(poses, dtype=np.float64)

    def _truth(self) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
        tp = self.topics.truth
        ts, poses = [], []
        for msg in self.messages(tp):
            p = msg.pose
            ts.append(m.header_ns(msg.header))
            poses.append((p.position.x, p.position.y, m.quaternion_yaw(p.orientation)))
        if not ts:
            return None, None
        self._ordered(tp, ts, self.path)
        return np.asarray(ts, dtype=np.int64), np.asarray(poses, dtype=np.float64)

    def _depth_stamps(self) -> np.ndarray:
        """The depth images' header stamps, checked in order, with their size and encoding."""
        tp = self.topics.depth
        for _, w, h, enc in self._depth_headers:
            if (w, h) != self._size:
                raise InputError(
                    f"{self.path}: topic {tp}: a {w} x {h} image, but {self.topics.camera_info} "
                    f"describes {self._size[0]} x {self._size[1]}"
                )
            if enc.upper() not in m.DEPTH_ENCODINGS:
                raise InputError(f"{self.path}: topic {tp}: depth image encoding {enc!r}; expected 32FC1 (metres) or 16UC1 (millimetres)")
        if not self._depth_headers:
            raise InputError(f"{self.path}: topic {tp} has no message")
        ts = [h[0] for h in self._depth_headers]
        self._ordered(tp, ts, self.path)
        return np.asarray(ts, dtype=np.int64)

    # -- the frames -----------------------------------------------------------------------
    def odom_at(self, t_ns: int) -> np.ndarray:
        """The odometry pose at ``t_ns``: the message with that stamp, else interpolated
        between its neighbours (heading along the shorter way)."""
        ts, ps = self.odom_t, self.odom_poses
        i = int(np.searchsorted(ts, t_ns))
        if i < len(ts) and ts[i] == t_ns:
            return ps[i].copy()
        i = min(max(i, 1), len(ts) - 1)
        a, b = ps[i - 1], ps[i]
        f = float(t_ns - ts[i - 1]) / float(ts[i] - ts[i - 1])
        th = a[2] + f * wrap_angle(float(b[2] - a[2]))
        return np.array([a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), wrap_angle(th)])

    def frame_stamps(self) -> list[tuple[int, bool]]:
        """(stamp, has an image) of every frame to step on: the depth images within the
        odometry's span, and where a gap between two of them is longer than
        ``DROPPED_GAP`` usual intervals, the frames the camera dropped (at the odometry's
        stamps in the gap when it has one per missing frame, else evenly spaced)."""
        d = self.depth_stamps
        d = d[(d >= self.odom_t[0]) & (d <= self.odom_t[-1])]
        if len(d) == 0:
            raise InputError(f"{self.path}: no depth image on {self.topics.depth} lies within the odometry's span on {self.topics.odom}")
        usual = float(np.median(np.diff(d))) if len(d) > 1 else 0.0
        out: list[tuple[int, bool]] = [(int(d[0]), True)]
        for a, b in zip(d[:-1], d[1:], strict=True):
            gap = float(b - a)
            if usual > 0 and gap > DROPPED_GAP * usual:
                k = int(round(gap / usual)) - 1
                inside = self.odom_t[(self.odom_t > a) & (self.odom_t < b)]
                stamps = inside if len(inside) == k else a + np.round(np.arange(1, k + 1) * gap / (k + 1)).astype(np.int64)
                out.extend((int(s), False) for s in stamps)
            out.append((int(b), True))
        return out

    def frames(self) -> Iterator[BagFrame]:
        """The frames in order (:meth:`frame_stamps`), the images decoded one at a time."""
        plan = self.frame_stamps()
        # The plan's images are a subsequence of the topic's, in the same order: skip
        # those outside the odometry's span.
        images = ((m.header_ns(msg.header), msg) for _, msg in self._messages(self.topics.depth))
        for stamp, has_image in plan:
            depth = None
            if has_image:
                for s, msg in images:
                    if s == stamp:
                        try:
                            depth = m.image_depth(msg, self.topics.depth)
                        except ValueError as exc:
                            raise InputError(f"{self.path}: {exc}") from None
                        break
            yield BagFrame(stamp / 1e9, depth, self.odom_at(stamp))

    def truth_at(self, t_ns: int) -> np.ndarray | None:
        """The ground truth at ``t_ns`` (the message with that stamp, else the nearest within 20 ms)."""
        if self.truth_t is None:
            return None
        i = int(np.searchsorted(self.truth_t, t_ns))
        best = None
        for j in (i - 1, i):
            if 0 <= j < len(self.truth_t) and abs(int(self.truth_t[j]) - t_ns) <= 20_000_000:
                if best is None or abs(int(self.truth_t[j]) - t_ns) < abs(int(self.truth_t[best]) - t_ns):
                    best = j
        return None if best is None else self.truth_poses[best].copy()


def _ancestors(edges: dict, frame: str) -> set[str]:
    out, f = {frame}, frame
    while f in edges and edges[f][0] not in out:
        f = edges[f][0]
        out.add(f)
    return out


def mount_from_transform(rot: np.ndarray, trans: np.ndarray, what: str) -> CameraMount:
    """A :class:`CameraMount` from the robot -> optical frame rotation and translation;
    a roll or yaw beyond ``MOUNT_TOLERANCE_RAD`` is an error naming ``what``."""
    r_y = np.asarray(rot, dtype=np.float64) @ ROBOT_FROM_OPTICAL_LEVEL.T
    pitch = math.atan2(r_y[0, 2], r_y[0, 0])
    c, s = math.cos(pitch), math.sin(pitch)
    expect = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    off = math.acos(max(-1.0, min(1.0, (np.trace(expect.T @ r_y) - 1.0) / 2.0)))
    if off > MOUNT_TOLERANCE_RAD:
        raise InputError(
            f"{what}: the camera rolls or yaws by {math.degrees(off):.2f} degrees; the stack models a camera pitched "
            "about the robot's y axis (give the mount with --mount height,forward,lateral,pitch_deg)"
        )
    return CameraMount(height_m=float(trans[2]), forward_m=float(trans[0]), lateral_m=float(trans[1]), pitch_down_rad=float(pitch))


def open_bag(path: str | Path, topics: BagTopics = DEFAULT_TOPICS, mount: CameraMount | None = None) -> BagSource:
    """Open and check a bag for replay (:class:`BagSource`)."""
    return BagSource(path, topics, mount)
