"""Recorded drives: depth frames, odometry and ground truth, recorded once, replayed many times.

BV2012, VI-A: "We recorded a log with odometry and data from the Kinect sensor ...
This log was replayed offline for the different localization approaches". A
:class:`RecordingConfig` names a building, a route, unmapped furniture and people; the
recorder drives the robot along the route in the simulator (the navigator on the true
pose, avoiding what FSPF senses, as the runner's ``ground_truth`` follower does), and
stores every Kinect frame with the robot's true pose and the noise-free odometry
increment since the previous frame. Replays add their own odometry noise.

Storage (``<cache_dir>/<name>-<key>.log.npz``, ``np.savez_compressed``): ``depth_mm``
(N, H, W) uint16 millimetres (0 = invalid, as the Kinect), ``t`` (N,) seconds,
``poses`` (N, 3) true x, y, theta at each frame, ``increments`` (N, 3) true robot-frame
odometry from the previous frame (zero for frame 0), ``people`` (N, P, 3) float32,
and ``meta`` (JSON: camera intrinsics and mount, map, route, the recording config).
The key is a hash of the recording parameters, so a log is reused across runs and
re-recorded when they change. Replays read depth from an uncompressed working copy
(``.depth.npy``, memory-mapped, so processes on one machine share its pages), unpacked
from the compressed log on first use. Recording and unpacking take a file lock and
write to a temporary name first: concurrent workers never see half a file.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import math
import os
import sys
import time
import zipfile
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.files import atomic_path
from autonomy.common.geometry import relative_pose
from autonomy.navigation.avoidance import AvoidanceConfig
from autonomy.navigation.config import NavigatorConfig
from autonomy.perception.camera import CameraIntrinsics, CameraMount
from autonomy.perception.fspf import FSPFConfig
from sim.config import to_dict
from sim.experiments.report_file import config_json
from sim.simulator.actors import Furniture, Person
from sim.simulator.kinect import KinectConfig
from sim.simulator.robot import RobotConfig, avoidance_for_body
from sim.simulator.step import SimFrame
from sim.simulator.world import WorldConfig

#: Bump when the recorder or the file layout changes meaning (invalidates cached logs).
LOG_VERSION = 2


@dataclass(frozen=True)
class RecordingConfig:
    """The drive that is recorded once: building, route, actors, sensor (BV2012, VI-A)."""

    map: str = "corridor_loop"
    """A building shipped in sim/assets."""
    route: tuple[tuple[float, float], ...] = ()
    """(x, y) points to drive through in order; each snaps to its nearest nav-graph node
    (the first is the start). At least two."""
    start_heading_rad: float = math.nan
    """Initial heading; NaN = towards the second route point."""
    max_duration_s: float = 90.0
    """Stop recording after this much simulated time (or when the route is done)."""
    seed: int = 0
    """Seed of the recording (sensor noise, FSPF for the recording robot's avoidance)."""
    furniture: tuple[Furniture, ...] = ()
    """Unmapped furniture."""
    people: tuple[Person, ...] = ()
    """People walking routes (speed 0 = standing)."""
    world: WorldConfig = field(default_factory=WorldConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    kinect: KinectConfig = field(default_factory=KinectConfig)
    fspf: FSPFConfig = field(default_factory=FSPFConfig)
    """FSPF of the recording robot's obstacle avoidance (replays run their own)."""
    navigator: NavigatorConfig = field(default_factory=NavigatorConfig)
    avoidance: AvoidanceConfig = field(default_factory=AvoidanceConfig)
    waypoint_timeout_s: float = 60.0
    """Give a route point up after this long and go on to the next."""

    def __post_init__(self) -> None:
        if len(self.route) < 2:
            raise InputError("recording.route: expected at least two (x, y) points")
        for p in self.route:
            if len(p) != 2 or not all(math.isfinite(float(c)) for c in p):
                raise InputError(f"recording.route point {p!r}: expected two finite numbers")
        if not (math.isfinite(self.max_duration_s) and self.max_duration_s > 0):
            raise InputError("recording.max_duration_s: expected a positive number")
        if not self.waypoint_timeout_s > 0:
            raise InputError("recording.waypoint_timeout_s: expected a positive number")
        # The recording robot avoids with the body the simulator drives.
        object.__setattr__(self, "avoidance", avoidance_for_body(self.avoidance, self.robot, "recording"))

    def key(self) -> str:
        """Hash of everything that changes the recorded log."""
        payload = json.dumps({"version": LOG_VERSION, "config": config_json(to_dict(self))}, sort_keys=True)
        return hashlib.sha256(payload.encode()).hexdigest()[:16]




@dataclass
class DriveLog:
    """A recorded drive, depth possibly memory-mapped."""

    depth_mm: np.ndarray
    """(N, H, W) uint16 millimetres, 0 = invalid."""
    t: np.ndarray
    """(N,) seconds since the start."""
    poses: np.ndarray
    """(N, 3) true pose at each frame."""
    increments: np.ndarray
    """(N, 3) noise-free odometry increment from the previous frame (robot frame)."""
    people: np.ndarray
    """(N, P, 3) people x, y, heading."""
    intrinsics: CameraIntrinsics
    mount: CameraMount
    map_name: str
    meta: dict
    path: Path | None = None

    @property
    def n_frames(self) -> int:
        return int(len(self.t))

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self.t) > 1 else 0.0

    @property
    def distance_m(self) -> float:
        return float(np.hypot(*np.diff(self.poses[:, :2], axis=0).T).sum()) if len(self.t) > 1 else 0.0


def default_cache_dir() -> Path:
    """``$DEPTHNAV_CACHE/logs`` or ``~/.cache/depthnav/logs``."""
    base = os.environ.get("DEPTHNAV_CACHE")
    return (Path(base) if base else Path.home() / ".cache" / "depthnav") / "logs"


def log_path(cfg: RecordingConfig, cache_dir: str | Path | None, name: str = "drive") -> Path:
    d = Path(cache_dir) if cache_dir else default_cache_dir()
    return d / f"{name}-{cfg.key()}.log.npz"


@contextmanager
def _locked(path: Path):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(str(path) + ".lock", "w") as lf:
        fcntl.flock(lf, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lf, fcntl.LOCK_UN)


def _working_copy(path: Path) -> Path:
    return path.with_name(path.name.removesuffix(".log.npz") + ".depth.npy")


def _valid_log(path: Path) -> bool:
    try:
        with zipfile.ZipFile(path) as z:
            names = set(z.namelist())
        return {"depth_mm.npy", "t.npy", "poses.npy", "increments.npy", "meta.npy"} <= names
    except (OSError, zipfile.BadZipFile):
        return False


def ensure_log(cfg: RecordingConfig, cache_dir: str | Path | None, name: str = "drive", progress: bool = False) -> Path:
    """The log's path, recording it first if it is not in the cache (safe across processes)."""
    path = log_path(cfg, cache_dir, name)
    if _valid_log(path):
        return path
    with _locked(path):
        if not _valid_log(path):
            try:
                record_log(cfg, path, progress=progress)
            except BaseException:
                for p in path.parent.glob(f"{path.name.removesuffix('.log.npz')}*.{os.getpid()}.tmp*"):
                    p.unlink(missing_ok=True)
                raise
    return path


def _unpack_depth(path: Path, out: Path) -> None:
    """Stream the compressed depth of a log into an uncompressed .npy (atomically)."""
    with zipfile.ZipFile(path) as z, z.open("depth_mm.npy") as f, atomic_path(out) as tmp:
        version = np.lib.format.read_magic(f)
        read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran, dtype = read_header(f)
        if fortran or dtype != np.uint16 or len(shape) != 3:
            raise InputError(f"{path}: depth_mm is not a C-ordered (N, H, W) uint16 array")
        mm = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.uint16, shape=shape)
        frame_bytes = int(shape[1] * shape[2] * 2)
        for k in range(shape[0]):
            mm[k] = np.frombuffer(f.read(frame_bytes), dtype=np.uint16).reshape(shape[1:])
        mm.flush()
        del mm


def load_log(path: str | Path, mmap: bool = True) -> DriveLog:
    """Read a log; depth memory-mapped from its working copy (unpacked on first use)."""
    path = Path(path)
    if not _valid_log(path):
        raise InputError(f"{path}: not a depthnav drive log")
    with np.load(path, allow_pickle=False) as z:
        t, poses, inc = z["t"], z["poses"], z["increments"]
        people = z["people"] if "people" in z.files else np.zeros((len(t), 0, 3), np.float32)
        meta = json.loads(str(z["meta"]))
        depth = None if mmap else z["depth_mm"]
    if depth is None:
        wc = _working_copy(path)
        need = not wc.is_file()
        if not need:
            try:
                depth = np.load(wc, mmap_mode="r")
                need = depth.shape[0] != len(t) or depth.dtype != np.uint16
            except (OSError, ValueError):
                need = True
        if need:
            with _locked(path):
                try:
                    depth = np.load(wc, mmap_mode="r")
                    ok = depth.shape[0] == len(t)
                except (OSError, ValueError):
                    ok = False
                if not ok:
                    _unpack_depth(path, wc)
            depth = np.load(wc, mmap_mode="r")
    intr = CameraIntrinsics(**meta["intrinsics"])
    mount = CameraMount(**meta["mount"])
    return DriveLog(depth, t, poses, inc, people, intr, mount, meta["map"], meta, path)


def _route_nodes(graph, route: tuple[tuple[float, float], ...]) -> list[int]:
    xy = graph.node_xy()
    ids = [int(i) for i in graph.node_ids()]
    out: list[int] = []
    for p in route:
        j = int(np.argmin(np.hypot(xy[:, 0] - p[0], xy[:, 1] - p[1])))
        if not out or out[-1] != ids[j]:
            out.append(ids[j])
    if len(out) < 2:
        raise InputError("recording.route: the route's points snap to fewer than two distinct nav-graph nodes")
    return out


def _truncate_npy(path: Path, n: int) -> None:
    """Keep the first ``n`` rows of an (N, ...) .npy in place: rewrite the header's shape
    (same header length; .npy headers are padded) and truncate the file."""
    import io

    with open(path, "r+b") as f:
        version = np.lib.format.read_magic(f)
        read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran, dtype = read_header(f)
        offset = f.tell()
        if shape[0] == n:
            return
        new = io.BytesIO()
        hdr = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": fortran, "shape": (n, *shape[1:])}
        (np.lib.format.write_array_header_1_0 if version == (1, 0) else np.lib.format.write_array_header_2_0)(new, hdr)
        if len(new.getvalue()) != offset:  # pragma: no cover - .npy headers are padded to 64 bytes
            raise RuntimeError(f"{path}: cannot rewrite the .npy header in place")
        f.seek(0)
        f.write(new.getvalue())
        f.truncate(offset + n * int(np.prod(shape[1:])) * dtype.itemsize)


def _write_npz(path: Path, **arrays: np.ndarray) -> None:
    """Like ``np.savez_compressed`` (readable by ``np.load``), at zlib level 1: about 6x
    faster than savez's level 6 on depth frames for 10% more bytes."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        for name, a in arrays.items():
            with z.open(f"{name}.npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.asanyarray(a), allow_pickle=False)


def _start_pose(cfg: RecordingConfig, graph, nodes: list[int]) -> np.ndarray:
    xy = graph.node_xy()
    p0 = xy[graph.index_of(nodes[0])]
    p1 = xy[graph.index_of(nodes[1])]
    heading = cfg.start_heading_rad if math.isfinite(cfg.start_heading_rad) else math.atan2(p1[1] - p0[1], p1[0] - p0[0])
    return np.array([p0[0], p0[1], heading])


def _to_mm(depth: np.ndarray) -> np.ndarray:
    """Depth in metres -> uint16 millimetres, as the Kinect's driver gives it."""
    d = np.rint(depth * 1000.0)
    return np.clip(d, 0, 65535).astype(np.uint16)


class _Recording:
    """Frames, poses and people as they are recorded; depth goes to a memory map."""

    def __init__(self, path: Path, max_frames: int, shape: tuple[int, int]) -> None:
        self.tmp = _working_copy(path).with_name(f"{_working_copy(path).name}.{os.getpid()}.tmp")
        self.depth = np.lib.format.open_memmap(self.tmp, mode="w+", dtype=np.uint16, shape=(max_frames, *shape))
        self.t: list[float] = []
        self.poses: list[np.ndarray] = []
        self.people: list[np.ndarray] = []

    def add(self, frame: SimFrame, people: np.ndarray) -> np.ndarray:
        """Store a frame; returns its depth as the robot reads it back (metres, from mm)."""
        k = len(self.t)
        self.depth[k] = _to_mm(frame.depth)
        self.t.append(frame.t)
        self.poses.append(frame.pose)
        self.people.append(people.astype(np.float32).reshape(-1, 3))
        return self.depth[k].astype(np.float32) * np.float32(0.001)


def record_log(cfg: RecordingConfig, path: str | Path, *, progress: bool = False) -> Path:
    """Drive the route in the simulator and write the log to ``path`` (atomically).

    The recording robot is the robot stack without localization, navigating on the true
    pose, sensing the millimetre depth it records (as a replay reads it).
    """
    from autonomy.stack import LocalizationConfig, RobotStack, StackConfig
    from sim.simulator import blueprints
    from sim.simulator.blueprints import ASSETS_DIR
    from sim.simulator.kinect import KinectCamera
    from sim.simulator.robot import Odometry, OdometryConfig
    from sim.simulator.step import SimStep
    from sim.simulator.world import build_world

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not (ASSETS_DIR / f"{cfg.map}.vectormap.txt").is_file():
        raise InputError(f"recording.map: no building {cfg.map!r} in sim/assets")
    bp = blueprints.load_blueprint(ASSETS_DIR / cfg.map)
    vm, graph = bp.vectormap, bp.navgraph
    nodes = _route_nodes(graph, cfg.route)
    start = _start_pose(cfg, graph, nodes)
    kin = cfg.kinect
    intr = kin.intrinsics
    world = build_world(
        vm, world=cfg.world, robot=cfg.robot, intrinsics=intr, mount=kin.mount,
        furniture=cfg.furniture, people=cfg.people, start_pose=tuple(start),
    )
    noise_seed, fspf_seed = (int(v) for v in np.random.default_rng(np.random.SeedSequence(cfg.seed)).integers(0, 2**31, size=2))
    # The log keeps the true increments (replays add their own noise): noise-free odometry.
    odometry = Odometry(OdometryConfig(0.0, 0.0, 0.0), np.random.default_rng(0), start)
    sim = SimStep(world, KinectCamera(world.model, world.camera_id, kin), odometry, noise_seed)
    scfg = StackConfig(kin.depth_camera(), cfg.fspf, LocalizationConfig(enabled=False), cfg.avoidance, cfg.navigator)
    stack = RobotStack(vm, graph, scfg, rng=np.random.default_rng(0), fspf_seed=fspf_seed)
    stack.reset(start)
    max_frames = int(math.ceil(cfg.max_duration_s / sim.frame_dt)) + 1
    rec = _Recording(path, max_frames, (intr.height, intr.width))
    events: list[dict] = []
    collisions = 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=max_frames, unit="frame", desc="recording the drive", leave=False, file=sys.stderr)
    wall0 = time.perf_counter()
    current = 1
    stack.set_goal(nodes[current], 0.0, start)
    frame = sim.first()
    out = stack.step(rec.add(frame, world.people.positions()), None, frame.t, frame.pose)
    leg_start = 0.0
    try:
        while len(rec.t) < max_frames:
            t = float(world.data.time)
            pose = world.robot.pose(world.data)
            cmd = out.command
            assert cmd is not None
            if cmd.state == "arrived" or t - leg_start > cfg.waypoint_timeout_s:
                events.append({"t": round(t, 3), "node": nodes[current], "status": "reached" if cmd.state == "arrived" else "timeout"})
                current += 1
                if current >= len(nodes):
                    break
                stack.set_goal(nodes[current], t, pose)
                leg_start = t
                cmd = stack.redecide(t, pose).command
                assert cmd is not None
            frame = sim.step(cmd.velocity)
            collisions += frame.new_contacts
            # Decided on the true pose of the frame (the recording robot does not localize).
            out = stack.step(rec.add(frame, world.people.positions()), frame.increment, frame.t, frame.pose)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        sim.camera.close()
    meta_extra = {"events": events, "collisions": collisions, "completed": current >= len(nodes), "record_wall_s": round(time.perf_counter() - wall0, 2)}
    _write_log(cfg, path, rec, nodes, meta_extra)
    return path


def _write_log(cfg: RecordingConfig, path: Path, rec: _Recording, nodes: list[int], extra: dict) -> None:
    """The compressed log and its uncompressed working copy, each renamed into place."""
    kin = cfg.kinect
    n = len(rec.t)
    rec.depth.flush()
    poses_a = np.array(rec.poses)
    inc = np.zeros((n, 3))
    for i in range(1, n):
        inc[i] = relative_pose(poses_a[i - 1], poses_a[i])
    meta = {
        "version": LOG_VERSION,
        "key": cfg.key(),
        "map": cfg.map,
        "route_nodes": nodes,
        "intrinsics": to_dict(kin.intrinsics),
        "mount": to_dict(kin.mount),
        "rate_hz": kin.rate_hz,
        "frames": n,
        "duration_s": round(rec.t[-1] - rec.t[0], 4),
        "distance_m": round(float(np.hypot(*np.diff(poses_a[:, :2], axis=0).T).sum()), 3),
        "collisions": extra["collisions"],
        "events": extra["events"],
        "completed": extra["completed"],
        "record_wall_s": extra["record_wall_s"],
        "config": config_json(to_dict(cfg)),
    }
    depth = rec.depth[:n]
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp.npz")
    _write_npz(
        tmp, depth_mm=depth, t=np.array(rec.t), poses=poses_a, increments=inc,
        people=np.array(rec.people, dtype=np.float32), meta=np.array(json.dumps(meta)),
    )
    del depth
    rec.depth = None  # close the memory map before the file is truncated
    _truncate_npy(rec.tmp, n)
    # Not autonomy.common.files.atomic_path: the working copy, recorded into since the start (its
    # temporary removed by ensure_log on failure), goes into place before the log does.
    os.replace(rec.tmp, _working_copy(path))
    os.replace(tmp, path)
