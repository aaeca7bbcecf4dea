"""ROS 2 bags: a run written as rosbag2 MCAP, read by other tools, replayed through the
robot stack to the same estimate; bad bags refused in one line naming the topic."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from autonomy.common.errors import InputError
from autonomy.perception.camera import CameraIntrinsics, CameraMount
from sim.cli import main
from sim.rosbag import messages as m
from sim.rosbag.reader import BagTopics, mount_from_transform, open_bag
from sim.rosbag.replay import replay_bag
from sim.rosbag.run_bag import TOPICS
from sim.rosbag.writer import BagWriter

INTR = CameraIntrinsics(width=8, height=6, fx=5.0, fy=5.0, cx=3.5, cy=2.5)

EXPECTED_TOPICS = {
    TOPICS.depth: m.IMAGE, TOPICS.camera_info: m.CAMERA_INFO, TOPICS.odom: m.ODOMETRY, TOPICS.tf: m.TF,
    TOPICS.tf_static: m.TF, TOPICS.estimate: m.POSE_COV, TOPICS.truth: m.POSE, TOPICS.points: m.CLOUD,
    TOPICS.scan: m.SCAN, TOPICS.map: m.MARKERS, TOPICS.cmd_vel: m.TWIST, TOPICS.run: m.STRING,
}


def _synthetic_bag(path: Path, *, n: int = 6, depth_encoding: str = "32FC1", skip_frames: tuple[int, ...] = (),
                   swap_odom: int | None = None, info=None, image=None, mount: CameraMount = CameraMount(),
                   omit: tuple[str, ...] = ()) -> Path:
    """A small bag as a robot would record it: depth images, camera info, odometry, tf."""
    with BagWriter(path) as b:
        if "tf_static" not in omit:
            b.write(TOPICS.tf_static, 0, m.tf_message(m.mount_transforms(0, mount)))
        stamps = [k * 33_333_333 for k in range(n)]
        if swap_odom is not None:
            stamps[swap_odom], stamps[swap_odom + 1] = stamps[swap_odom + 1], stamps[swap_odom]
        for k in range(n):
            ns = k * 33_333_333
            if k not in skip_frames and "depth" not in omit:
                d = np.full((INTR.height, INTR.width), 1.0 + 0.01 * k, dtype=np.float32)
                b.write(TOPICS.depth, ns, image(ns, d) if image else m.depth_image(ns, d, depth_encoding))
                b.write(TOPICS.camera_info, ns, info(ns) if info else m.camera_info(ns, INTR))
            if "odom" not in omit:
                b.write(TOPICS.odom, ns, m.odometry(stamps[k], np.array([0.1 * k, 0.0, 0.01 * k]), np.zeros(3)))
    return path


def test_messages_round_trip_poses_and_depth() -> None:
    for yaw in (-3.0, -0.5, 0.0, 1.2, 3.1):
        assert m.quaternion_yaw(m.yaw_quaternion(yaw)) == pytest.approx(yaw, abs=1e-12)
    d = np.array([[0.0, 0.8004, 1.25], [3.9999, np.nan, 2.0]], dtype=np.float32)
    exact = m.image_depth(m.depth_image(0, d, "32FC1"), "/d")
    assert exact.dtype == np.float32 and np.array_equal(exact, np.nan_to_num(d))
    mm = m.image_depth(m.depth_image(0, d, "16UC1"), "/d")
    assert np.allclose(mm, np.round(np.nan_to_num(d) * 1000) / 1000, atol=1e-6)
    pts = np.array([[1.0, 2.0, 3.0], [-0.5, 0.25, 0.0]])
    assert np.allclose(m.cloud_points(m.point_cloud(0, pts)), pts)


@settings(max_examples=60, deadline=None)
@given(
    height=st.floats(0.1, 2.0), forward=st.floats(-0.5, 0.5), lateral=st.floats(-0.3, 0.3), pitch=st.floats(-0.6, 1.2),
)
def test_the_mount_survives_tf(height: float, forward: float, lateral: float, pitch: float) -> None:
    mount = CameraMount(height_m=height, forward_m=forward, lateral_m=lateral, pitch_down_rad=pitch)
    base_cam, cam_opt, _ = m.mount_transforms(0, mount)
    r1, r2 = (m.quaternion_matrix(t.transform.rotation) for t in (base_cam, cam_opt))
    t1 = base_cam.transform.translation
    got = mount_from_transform(r1 @ r2, np.array([t1.x, t1.y, t1.z]), "test")
    assert np.allclose(got.robot_from_camera(), mount.robot_from_camera(), atol=1e-9)


def test_a_rolled_camera_is_refused() -> None:
    mount = CameraMount()
    c, s = math.cos(0.1), math.sin(0.1)
    roll = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    with pytest.raises(InputError, match="rolls or yaws"):
        mount_from_transform(roll @ mount.rotation(), mount.translation(), "test")


def test_a_synthetic_bag_gives_the_camera_mount_and_frames(tmp_path: Path) -> None:
    mount = CameraMount(height_m=0.5, forward_m=0.1, lateral_m=0.02, pitch_down_rad=0.2)
    src = open_bag(_synthetic_bag(tmp_path / "b.mcap", mount=mount, skip_frames=(3,)))
    try:
        assert src.intrinsics == INTR
        assert np.allclose(src.mount.robot_from_camera(), mount.robot_from_camera(), atol=1e-12)
        frames = list(src.frames())
    finally:
        src.close()
    # The dropped frame is a frame without an image, at the odometry's stamp.
    assert [f.depth is None for f in frames] == [False, False, False, True, False, False]
    assert frames[3].t == pytest.approx(3 * 0.033333333)
    assert np.allclose(frames[4].odom, [0.4, 0.0, 0.04])
    assert frames[5].depth[0, 0] == pytest.approx(1.05)


def test_odometry_between_messages_is_interpolated(tmp_path: Path) -> None:
    src = open_bag(_synthetic_bag(tmp_path / "b.mcap"))
    try:
        mid = src.odom_at(50_000_000)
    finally:
        src.close()
    assert np.allclose(mid, [0.15, 0.0, 0.015])


@pytest.mark.parametrize(
    "kwargs, topic, what",
    [
        ({"omit": ("depth",)}, TOPICS.depth, "no topic"),
        ({"omit": ("odom",)}, TOPICS.odom, "no topic"),
        ({"depth_encoding": "16UC1", "image": lambda ns, d: m._t(m.IMAGE)(
            header=m.header(ns, m.OPTICAL_FRAME), height=d.shape[0], width=d.shape[1], encoding="rgb8", is_bigendian=0,
            step=3 * d.shape[1], data=np.zeros(3 * d.size, np.uint8))}, TOPICS.depth, "encoding 'rgb8'"),
        ({"swap_odom": 2}, TOPICS.odom, "out of order"),
        ({"info": lambda ns: m.camera_info(ns, CameraIntrinsics(width=16, height=12, fx=5.0, fy=5.0, cx=7.5, cy=5.5))},
         TOPICS.depth, "describes 16 x 12"),
        ({"omit": ("tf_static",)}, TOPICS.tf_static, "no transform from base_link"),
    ],
)
def test_bad_bags_are_one_line_errors_naming_the_topic(tmp_path: Path, kwargs: dict, topic: str, what: str) -> None:
    path = _synthetic_bag(tmp_path / "bad.mcap", **kwargs)
    with pytest.raises(InputError) as err:
        open_bag(path).close()
    msg = str(err.value)
    assert topic in msg and what in msg and "\n" not in msg, msg


def test_distortion_is_refused(tmp_path: Path) -> None:
    def distorted(ns):
        info = m.camera_info(ns, INTR)
        info.d[0] = 0.1
        return info

    with pytest.raises(InputError, match=f"{TOPICS.camera_info}: distortion"):
        open_bag(_synthetic_bag(tmp_path / "d.mcap", info=distorted)).close()


def test_another_message_type_on_the_depth_topic_is_named(tmp_path: Path) -> None:
    path = tmp_path / "t.mcap"
    with BagWriter(path) as b:
        b.write(TOPICS.depth, 0, m.string("not an image"))
    with pytest.raises(InputError, match=f"topic {TOPICS.depth} carries std_msgs/msg/String; expected sensor_msgs/msg/Image"):
        open_bag(path).close()


def test_the_writer_refuses_stamps_that_go_back(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "w.mcap") as b:
        b.write("/x", 10, m.string("a"))
        with pytest.raises(ValueError, match="/x: stamp 5 ns goes back"):
            b.write("/x", 5, m.string("b"))


def test_cli_errors_are_one_line(tmp_path: Path, capsys) -> None:
    assert main(["replay", str(tmp_path / "missing.mcap")]) == 2
    assert "missing.mcap: no such bag" in capsys.readouterr().err
    assert main(["replay", str(_synthetic_bag(tmp_path / "b.mcap")), "--start", "1,2"]) == 2
    assert "--start '1,2': expected x,y,theta" in capsys.readouterr().err
    for bad, says in (("0.7,0.2,0", "expected height,forward,lateral,pitch_deg"), ("0.7,nan,0,17", "expected height"),
                      ("0,0.2,0,17", "the height must be above the floor")):
        assert main(["replay", str(tmp_path / "b.mcap"), "--mount", bad]) == 2
        err = capsys.readouterr().err
        assert f"--mount '{bad}': {says}" in err and "Traceback" not in err, err
    assert main(["run", "scenarios/demo.toml", "--bag", str(tmp_path / "run.bag")]) == 2
    assert "expected a file name ending in .mcap" in capsys.readouterr().err


@pytest.mark.slow
def test_a_run_round_trips_through_its_bag(tmp_path: Path, capsys) -> None:
    """``depthnav run --bag`` writes a bag the mcap reader and rosbags both read, with
    every topic and stamps in order; ``depthnav replay`` on it gives the run's estimate."""
    bag = tmp_path / "run.mcap"
    rc = main([
        "run", "scenarios/demo.toml", "--out", str(tmp_path / "run"), "--bag", str(bag), "--seed", "4",
        "--set", "mission.max_duration_s=4", "--set", 'map.name="small_floor"',
    ])
    assert rc == 0
    run = json.loads((tmp_path / "run" / "report.json").read_text())

    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    seen: dict[str, list[int]] = {}
    with open(bag, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            seen.setdefault(channel.topic, []).append(message.log_time)
            assert schema.name == EXPECTED_TOPICS.get(channel.topic, schema.name)
            if channel.topic == TOPICS.depth:
                assert decoded.encoding == "32FC1" and (decoded.width, decoded.height) == (640, 480)
    assert set(EXPECTED_TOPICS) <= set(seen)
    frames = run["metrics"]["frames"] + 1  # and the first frame, seen before moving
    assert len(seen[TOPICS.odom]) == frames and len(seen[TOPICS.depth]) == frames
    for topic, stamps in seen.items():
        assert np.all(np.diff(stamps) >= 0), topic

    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as r:
        assert {c.topic: c.msgtype for c in r.connections if c.topic in EXPECTED_TOPICS} == EXPECTED_TOPICS
        conn = next(c for c in r.connections if c.topic == TOPICS.scan)
        scan = r.deserialize(next(iter(r.messages(connections=[conn])))[2], conn.msgtype)
        assert scan.header.frame_id == m.LASER_FRAME and len(scan.ranges) > 100

    assert main(["replay", str(bag), "--out", str(tmp_path / "replay")]) == 0
    rep = json.loads((tmp_path / "replay" / "report.json").read_text())
    mt = rep["metrics"]
    assert mt["frames"] == frames and mt["recorded_estimate_frames"] == frames
    # The same seeds, frames and stack: the same estimate, to the rounding of odometry
    # carried as poses.
    assert mt["recorded_estimate_max_diff_m"] < 1e-9 and mt["recorded_estimate_max_diff_rad"] < 1e-9
    assert mt["loc_error_p95_m"] == pytest.approx(run["metrics"]["loc_error_p95_m"], abs=1e-4)
    est = np.loadtxt(tmp_path / "replay" / "trajectory_estimate.tum")
    ran = np.loadtxt(tmp_path / "run" / "trajectory_estimate.tum")
    assert est.shape == ran.shape and np.allclose(est[:, 1:3], ran[:, 1:3], atol=1e-6)
    assert "replay:" in capsys.readouterr().out


def test_replay_with_another_topic_name_reads_it(tmp_path: Path) -> None:
    """A robot's own topic names are given as options; the stack runs on the frames."""
    path = tmp_path / "b.mcap"
    with BagWriter(path) as b:
        b.write(TOPICS.tf_static, 0, m.tf_message(m.mount_transforms(0, CameraMount())))
        intr = CameraIntrinsics()
        for k in range(4):
            ns = 1_000_000_000 + k * 33_333_333
            b.write("/kinect/depth", ns, m.depth_image(ns, np.full((intr.height, intr.width), 2.0, np.float32), "16UC1"))
            b.write("/kinect/info", ns, m.camera_info(ns, intr))
            b.write("/wheels", ns, m.odometry(ns, np.array([0.02 * k, 0.0, 0.0]), np.zeros(3)))
    rep = replay_bag(
        path, tmp_path / "out", map_path="small_floor", start=np.array([1.0, 1.0, 0.0]),
        topics=BagTopics(depth="/kinect/depth", camera_info="/kinect/info", odom="/wheels"),
    )
    assert rep["metrics"]["frames"] == 4 and rep["start_from"] == "--start"
    assert rep["stack_config_from"] == "the defaults"
    tum = np.loadtxt(tmp_path / "out" / "trajectory_estimate.tum")
    assert tum.shape == (4, 8) and tum[0, 0] == pytest.approx(1.0)


def test_a_ros1_bag_reads_as_its_rosbag2_original(tmp_path: Path) -> None:
    """ROS 1 bags (the CoBot era's) are read too: the same bag converted by rosbags
    gives the same camera, mount and frames."""
    from rosbags.convert import convert
    from rosbags.typesys import Stores, get_typestore

    src2 = _synthetic_bag(tmp_path / "b.mcap", skip_frames=(2,))
    convert(
        [src2], tmp_path / "b.bag", dst_storage="sqlite3", dst_version=None, compress=None, compress_mode="file",
        default_typestore=get_typestore(Stores.ROS1_NOETIC), typestore=None, exclude_topics=(), include_topics=(),
        exclude_msgtypes=(), include_msgtypes=(),
    )
    a, b = open_bag(src2), open_bag(tmp_path / "b.bag")
    try:
        assert a.intrinsics == b.intrinsics and a.mount == b.mount
        for fa, fb in zip(a.frames(), b.frames(), strict=True):
            assert fa.t == fb.t and np.array_equal(fa.odom, fb.odom)
            assert (fa.depth is None and fb.depth is None) or np.array_equal(fa.depth, fb.depth)
    finally:
        a.close()
        b.close()


def test_a_recorded_drive_is_written_as_a_bag(tmp_path: Path, capsys) -> None:
    """The localization comparison's recorded drives export too: the millimetre depth
    they store exactly, their noise-free odometry, the truth and the map's walls."""
    from sim.experiments.drives import RecordingConfig, load_log, record_log

    path = tmp_path / "d.log.npz"
    record_log(RecordingConfig(map="small_floor", route=((3.9, 5.1), (3.9, 6.95)), max_duration_s=1.0), path)
    log = load_log(path)
    assert main(["bag", str(path), "--out", str(tmp_path / "d.mcap")]) == 0
    assert f"{log.n_frames} frames" in capsys.readouterr().out
    src = open_bag(tmp_path / "d.mcap")
    try:
        frames = list(src.frames())
        assert len(frames) == log.n_frames and src.intrinsics == log.intrinsics
        assert np.array_equal(np.rint(frames[-1].depth * 1000).astype(np.uint16), np.asarray(log.depth_mm[-1]))
        assert np.allclose(src.truth_poses, log.poses) and len(src.messages(src.topics.walls)) == 1
        assert src.messages(src.topics.estimate) == []
    finally:
        src.close()
    assert main(["bag", str(path), "--out", str(tmp_path / "d.bag")]) == 2


def test_replay_with_a_goal_records_the_navigators_commands(tmp_path: Path, capsys) -> None:
    """``--goal``: the navigator decides on each frame's estimate, nothing actuated."""
    bag = tmp_path / "run.mcap"
    assert main([
        "run", "scenarios/demo.toml", "--out", str(tmp_path / "run"), "--bag", str(bag), "--seed", "4",
        "--set", "mission.max_duration_s=2", "--set", 'map.name="small_floor"',
    ]) == 0
    assert main(["replay", str(bag), "--out", str(tmp_path / "r"), "--map", "small_floor", "--goal", "3.9,6.9"]) == 0
    rep = json.loads((tmp_path / "r" / "report.json").read_text())
    cmds = np.genfromtxt(tmp_path / "r" / "commands.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert len(cmds) == rep["metrics"]["frames"] and sum(rep["metrics"]["nav_states"].values()) == len(cmds)
    assert np.isfinite(cmds["vx"]).all()
    assert main(["replay", str(bag), "--goal", "3.9"]) == 2
    assert "--goal '3.9': expected x,y" in capsys.readouterr().err
