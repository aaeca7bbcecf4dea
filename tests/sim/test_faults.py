"""Fault injection (sim/simulator/fault_config.py, faults.py): the [faults] table, the schedule, and each
fault kind against what it should do to the world, the frames and the odometry."""

from __future__ import annotations

import math
import tomllib
import tracemalloc

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.common.geometry import compose_pose, point_segment_distance, relative_pose
from autonomy.maps.navgraph import NavEdge, NavGraph, NavNode
from autonomy.maps.planner import astar, path_points
from autonomy.perception.camera import CameraIntrinsics, CameraMount
from sim.config import from_dict, to_dict
from sim.simulator import blueprints
from sim.simulator.actors import PARK_XY, Furniture
from sim.simulator.blueprints import ASSETS_DIR
from sim.simulator.building import Building
from sim.simulator.fault_config import (
    FAULT_KINDS,
    FaultEvent,
    FaultSchedule,
    FaultsConfig,
    fault_actors,
    fault_rng,
)
from sim.simulator.faults import KEEP_OUT_M, KIDNAP_CLEARANCE_M, FaultInjector
from sim.simulator.kinect import KinectCamera, KinectConfig
from sim.simulator.robot import Odometry, OdometryConfig
from sim.simulator.step import SimStep
from sim.simulator.world import WorldConfig, build_world
from tests.helpers import GL, box_room

RADIUS = 0.3
NO_NOISE = OdometryConfig(0.0, 0.0, 0.0)
DEFAULT_ODOMETRY = OdometryConfig()
DEFAULT_MOUNT = CameraMount()
DEFAULT_WORLD = WorldConfig()
#: A 32 x 24 ray-cast camera: a real simulator step where the frame does not matter.
TINY = KinectConfig(intrinsics=CameraIntrinsics(width=32, height=24, fx=29.0, fy=29.0, cx=15.5, cy=11.5), backend="raycast")
needs_gl = pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")


def parse(text: str) -> FaultsConfig:
    return from_dict(FaultsConfig, tomllib.loads(text)["faults"], source="s.toml", prefix="faults")


def corridor_loop() -> Building:
    bp = blueprints.load_blueprint(ASSETS_DIR / "corridor_loop")
    return Building(bp.vectormap, bp.navgraph, tuple(bp.open_areas), tuple(bp.rooms), ASSETS_DIR / "corridor_loop.vectormap.txt")


class Rig:
    """A world with the faults' actors, its simulator step and an injector."""

    def __init__(
        self, cfg: FaultsConfig, building: Building, start, kinect: KinectConfig = TINY, odometry: OdometryConfig = DEFAULT_ODOMETRY,
        mount: CameraMount = DEFAULT_MOUNT, seed: int = 0, injector: bool = True, world: WorldConfig = DEFAULT_WORLD,
        furniture: tuple[Furniture, ...] = (),
    ) -> None:
        fault_furniture, people = fault_actors(cfg)
        furniture = furniture + fault_furniture
        self.building = building
        self.world = build_world(
            building.vectormap, world=world, intrinsics=kinect.intrinsics, mount=mount, furniture=furniture, people=people, start_pose=tuple(start)
        )
        self.camera = KinectCamera(self.world.model, self.world.camera_id, kinect)
        self.odometry = Odometry(odometry, np.random.default_rng(seed), np.asarray(start, dtype=float))
        self.sim = SimStep(self.world, self.camera, self.odometry, 1000 + seed)
        self.faults = FaultInjector(cfg, self.world, building, fault_rng(seed), self.odometry, RADIUS) if injector else None
        self.distance_m = 0.0

    def tick(self, velocity=(0.0, 0.0, 0.0), goal=None):
        """One tick as the runner does it: faults (``goal``: the mission's waypoint), the
        pose, the step, the filtered frame."""
        t = float(self.world.data.time)
        if self.faults is not None:
            self.faults.before_step(t, self.distance_m, goal)
        pose = self.world.robot.pose(self.world.data)
        frame = self.sim.step(np.asarray(velocity, dtype=float))
        self.distance_m += float(np.hypot(*(frame.pose[:2] - pose[:2])))
        return (self.faults.filter_frame(frame) if self.faults is not None else frame), pose

    def close(self) -> None:
        self.camera.close()


# --------------------------------------------------------------------------- configuration


def test_defaults_are_no_faults_and_the_documented_values() -> None:
    cfg = FaultsConfig()
    assert not cfg.enabled and cfg.events == () and cfg.every_m == 0.0
    assert fault_actors(cfg) == ((), ())
    assert cfg.kinds == FAULT_KINDS
    assert (cfg.blackout_s, cfg.burst_s, cfg.drop_probability, cfg.nan_fraction) == (5.0, 3.0, 0.5, 0.3)
    assert (cfg.slip_s, cfg.slip_speed_mps, cfg.bump_m, cfg.bump_deg, cfg.tilt_deg) == (2.0, 0.5, 0.3, 15.0, 4.0)
    assert (cfg.crowd_size, cfg.crowd_s, cfg.blockage_s) == (12, 60.0, 300.0)


def test_toml_round_trip_and_event_parameters() -> None:
    text = """
[faults]
every_m = 300.0
start_m = 100.0
kinds = ["kidnap", "blackout", "crowd", "blockage"]
blackout_s = 2.5
crowd_size = 4

[[faults.events]]
kind = "slip"
at_m = 50.0
bump_m = 0.5

[[faults.events]]
kind = "crowd"
at_s = 10.0
crowd_size = 7
"""
    cfg = parse(text)
    assert cfg.enabled and cfg.every_m == 300.0 and cfg.kinds == ("kidnap", "blackout", "crowd", "blockage")
    assert cfg.params_of(cfg.events[0]).bump_m == 0.5 and cfg.params_of(cfg.events[0]).slip_s == 2.0
    assert cfg.params_of(cfg.events[1]).crowd_size == 7
    # The world holds as many crowd people as the largest crowd, and the blockage's panels.
    furniture, people = fault_actors(cfg)
    assert len(people) == 7 and len(furniture) == cfg.n_panels() == 6
    assert from_dict(FaultsConfig, to_dict(cfg), source="x", prefix="faults") == cfg


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('kinds = ["kidnap", "blackout", "kidnapp"]', "s.toml: faults.kinds[2]: unknown fault 'kidnapp' (expected one of: kidnap, blackout, dropped,"),
        ("blackout_s = -1.0", "s.toml: faults.blackout_s: expected a positive number, got -1.0"),
        ("burst_s = 0", "s.toml: faults.burst_s: expected a positive number, got 0"),
        ("blockage_s = -5.0", "s.toml: faults.blockage_s: expected a number >= 0, got -5.0"),
        ("drop_probability = 1.5", "s.toml: faults.drop_probability: expected a number in [0, 1], got 1.5"),
        ("crowd_size = -2", "s.toml: faults.crowd_size: expected an integer >= 0, got -2"),
        ("every_m = -300.0", "s.toml: faults.every_m: expected a number >= 0, got -300.0"),
        ("every_m = 10.0\nkinds = []", "s.toml: faults.kinds: expected at least one kind with every_m > 0"),
        ("kind = 3", "s.toml: unknown key 'faults.kind' (expected one of:"),
        ('[[faults.events]]\nkind = "tilt"', "s.toml: faults.events[0]: give exactly one of 'at_m' (distance driven) or 'at_s'"),
        ('[[faults.events]]\nkind = "tilt"\nat_m = 1.0\nat_s = 2.0', "s.toml: faults.events[0]: give exactly one of"),
        ('[[faults.events]]\nkind = "blakout"\nat_m = 1.0', "s.toml: faults.events[0].kind: unknown fault 'blakout' (expected one of:"),
        ('[[faults.events]]\nkind = "blackout"\nat_m = -3.0', "s.toml: faults.events[0].at_m: expected a number >= 0, got -3.0"),
        ('[[faults.events]]\nkind = "blackout"\nat_s = 1.0\nblackout_s = -2.0', "s.toml: faults.events[0].blackout_s: expected a positive number"),
        ('[[faults.events]]\nkind = "blackout"\nat_s = 1.0\nburst_s = 2.0', "s.toml: faults.events[0].burst_s: not a parameter of 'blackout' (its parameters: blackout_s)"),
        ('[[faults.events]]\nkind = "kidnap"\nat_s = 1.0\nwhen = 2.0', "s.toml: unknown key 'faults.events[0].when' (expected one of:"),
        ('[[faults.events]]\nkind = "crowd"\nat_s = 1.0\ncrowd_size = 2.5', "s.toml: key 'faults.events[0].crowd_size' expected an integer, got float 2.5"),
    ],
)
def test_bad_input_is_one_line_naming_the_key(text: str, message: str) -> None:
    with pytest.raises(InputError) as err:
        parse(text if text.startswith("[[") else "[faults]\n" + text)
    assert str(err.value).startswith(message), str(err.value)
    assert "\n" not in str(err.value)


# --------------------------------------------------------------------------- schedule


def _periodic(seed: int, rounds: int = 2) -> list[str]:
    s = FaultSchedule(FaultsConfig(every_m=100.0, start_m=50.0), np.random.default_rng(seed))
    fired = []
    for d in np.arange(0.0, 50.0 + 100.0 * len(FAULT_KINDS) * rounds, 5.0):
        got = s.due(0.0, float(d))
        fired += [(float(d), kind) for kind, _, trigger in got if trigger == "every_m"]
    assert [d for d, _ in fired] == [50.0 + 100.0 * k for k in range(len(FAULT_KINDS) * rounds)]
    return [k for _, k in fired]


def test_every_m_cycles_through_all_kinds_in_a_seeded_order() -> None:
    a = _periodic(1)
    n = len(FAULT_KINDS)
    assert sorted(a[:n]) == sorted(FAULT_KINDS) and sorted(a[n:]) == sorted(FAULT_KINDS)
    assert _periodic(1) == a
    assert _periodic(2) != a
    assert a[:n] != list(FAULT_KINDS) or a[n:] != list(FAULT_KINDS)


def test_periodic_faults_stop_at_the_runs_distance() -> None:
    s = FaultSchedule(FaultsConfig(every_m=60.0), np.random.default_rng(0), until_m=700.0)
    fired = [d for d in np.arange(0.0, 900.0, 1.0) for _ in s.due(0.0, float(d))]
    assert fired == [60.0 * k for k in range(1, 12)]
    open_ended = FaultSchedule(FaultsConfig(every_m=60.0), np.random.default_rng(0), until_m=0.0)
    assert len([d for d in np.arange(0.0, 900.0, 1.0) for _ in open_ended.due(0.0, float(d))]) == 14  # 60 ... 840


def test_explicit_events_fire_once_at_their_distance_or_time() -> None:
    cfg = FaultsConfig(events=(FaultEvent(kind="blackout", at_m=10.0, blackout_s=1.0), FaultEvent(kind="stale", at_s=2.0)))
    s = FaultSchedule(cfg, np.random.default_rng(0))
    fired = []
    for k in range(200):
        t, d = k / 30.0, 0.1 * k
        fired += [(round(t, 4), round(d, 4), kind, p.blackout_s) for kind, p, _ in s.due(t, d)]
    assert fired == [(2.0, 6.0, "stale", 5.0), (round(100 / 30.0, 4), 10.0, "blackout", 1.0)]


# --------------------------------------------------------------------------- kidnap, slip


def test_kidnap_carries_the_robot_to_a_free_place_unseen_by_the_odometry() -> None:
    b = corridor_loop()
    n = 25
    cfg = FaultsConfig(events=tuple(FaultEvent(kind="kidnap", at_s=k / 30.0) for k in range(n)))
    start = np.array([12.0, 6.3, 0.0])
    rig = Rig(cfg, b, start, seed=3)
    walls = np.asarray(b.vectormap.segments)
    poses, spots = [], []
    for _ in range(n):
        before_odom = rig.odometry.pose.copy()
        frame, pose = rig.tick()
        ev = rig.faults.events[-1]
        assert ev["kind"] == "kidnap" and ev["t_end"] == ev["t_start"] and "skipped" not in ev
        assert np.allclose(ev["truth_after"], pose, atol=1e-6)
        spots.append(pose[:2])
        poses.append(pose)
        # Clearance against the map's segments, computed exactly here.
        assert point_segment_distance(pose[:2], walls).min() >= RADIUS + KIDNAP_CLEARANCE_M - 1e-9
        # The odometry: no jump in the increment nor in the dead-reckoned pose.
        assert np.abs(frame.increment).max() < 1e-3
        assert np.hypot(*(rig.odometry.pose[:2] - before_odom[:2])) < 1e-3
        assert np.abs(rig.world.robot.velocity_body(rig.world.data)).max() < 0.05  # stopped there
    spots = np.array(spots)
    # Anywhere in the building: the landing places spread over it, at random headings.
    assert np.ptp(spots[:, 0]) > 30.0 and np.ptp(spots[:, 1]) > 15.0
    assert np.ptp([p[2] for p in poses]) > 3.0
    rig.close()


def test_the_places_a_kidnap_lands_on_are_built_before_the_first_kidnap() -> None:
    """A run with kidnappings builds the building's free space and its landing cells
    when its injector is made: the first kidnap allocates no grid (a long run's memory
    stepped by about 20 MB at it)."""
    b = corridor_loop()
    cfg = FaultsConfig(events=(FaultEvent(kind="kidnap", at_s=0.0),))
    rig = Rig(cfg, b, np.array([12.0, 6.3, 0.0]), seed=4)
    tracemalloc.start()
    try:
        rig.faults.before_step(0.0, 0.0, None)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert rig.faults.events[-1]["kind"] == "kidnap" and "skipped" not in rig.faults.events[-1]
    assert peak < 1_000_000
    # Without the injector, the same first kidnap builds the grid (the check can fail).
    fresh = corridor_loop()
    tracemalloc.start()
    try:
        fresh.free_spot(np.random.default_rng(0), RADIUS + KIDNAP_CLEARANCE_M, RADIUS)
        _, peak_cold = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak_cold > 10_000_000
    rig.close()


def test_kidnap_keeps_clear_of_furniture_and_people() -> None:
    """In a small room with a cabinet and people, a landing place is 1 m from each of them."""
    vm = box_room(8.0, 6.0)
    b = Building(vm, _line_graph([(1.0, 1.0), (7.0, 1.0), (7.0, 5.0), (1.0, 5.0)]))
    crowd = FaultEvent(kind="crowd", at_s=0.0, crowd_size=3, crowd_radius_m=20.0)
    cfg = FaultsConfig(events=(crowd, *(FaultEvent(kind="kidnap", at_s=(k + 1) / 30.0) for k in range(20))))
    cabinet = Furniture(kind="cabinet", x=2.0, y=3.0, yaw=0.3)
    rig = Rig(cfg, b, (4.0, 3.0, 0.0), seed=5, furniture=(cabinet,))
    half = 0.5 * math.hypot(*cabinet.dims[:2])
    landed = 0
    for _ in range(21):
        _, pose = rig.tick()
        ev = rig.faults.events[-1]
        if ev["kind"] != "kidnap" or "skipped" in ev:
            continue
        landed += 1
        people = rig.world.people.positions()[:, :2]
        near = np.hypot(*(people - pose[:2]).T)
        assert near.min() >= RADIUS + 0.22 + KEEP_OUT_M - 0.1  # people walked one frame since
        assert math.hypot(pose[0] - cabinet.x, pose[1] - cabinet.y) >= RADIUS + half + KEEP_OUT_M - 1e-9
    assert landed >= 10
    rig.close()


def _line_graph(points) -> NavGraph:
    """A closed loop of nodes through ``points``."""
    nodes = tuple(NavNode(id=i, x=float(x), y=float(y)) for i, (x, y) in enumerate(points))
    edges = tuple(NavEdge(s0_id=i, s1_id=(i + 1) % len(points)) for i in range(len(points)))
    return NavGraph(nodes, edges)


def test_slip_reports_motion_that_did_not_happen_and_a_bump_moves_truth_not_odometry() -> None:
    vm = box_room(10.0, 6.0)
    b = Building(vm, _line_graph([(1.0, 1.0), (9.0, 1.0), (9.0, 5.0), (1.0, 5.0)]))
    slip = FaultEvent(kind="slip", at_s=1.0, slip_s=1.0, slip_speed_mps=0.4, bump_m=0.3, bump_deg=15.0)
    rig = Rig(FaultsConfig(events=(slip,)), b, (3.0, 3.0, 0.0), odometry=NO_NOISE)
    dt = rig.sim.frame_dt
    diffs, bumped = [], None
    for _ in range(90):
        odom_before = rig.odometry.pose.copy()
        frame, pose = rig.tick((0.3, 0.0, 0.0))
        ev = rig.faults.events[-1] if rig.faults.events else None
        if ev is not None and bumped is None:
            bumped = (np.array(ev["truth_before"]), np.array(ev["truth_after"]), ev)
        true_inc = relative_pose(pose, frame.pose)
        diffs.append((frame.t, frame.increment - true_inc))
        # The odometry's dead reckoning follows what the robot was told, increment by increment.
        assert np.allclose(rig.odometry.pose, compose_pose(odom_before, frame.increment), atol=1e-12)
    before, after, ev = bumped
    assert ev["t_start"] == pytest.approx(1.0, abs=1e-6) and ev["t_end"] == pytest.approx(2.0, abs=1e-6)
    assert math.hypot(*(after[:2] - before[:2])) == pytest.approx(0.3, abs=1e-6)
    assert abs(math.degrees(after[2] - before[2])) == pytest.approx(15.0, abs=1e-6)
    for t, d in diffs:
        inside = ev["t_start"] < t <= ev["t_end"] + 1e-9
        expected = np.array([0.4 * dt, 0.0, 0.0]) if inside else np.zeros(3)
        assert np.allclose(d, expected, atol=1e-9), (t, d)
    assert sum(ev["t_start"] < t <= ev["t_end"] + 1e-9 for t, _ in diffs) == 30
    rig.close()


# --------------------------------------------------------------------------- depth faults


@needs_gl
def test_depth_faults_on_real_frames_and_nothing_else_changes() -> None:
    """Blackout, dropped, corrupt_nan and stale on rendered Kinect frames of a turning
    robot, against the same run without faults: inside each burst the frame is what the
    fault says, outside it bit-identical."""
    vm = box_room(8.0, 6.0)
    b = Building(vm, _line_graph([(1.0, 1.0), (7.0, 1.0), (7.0, 5.0), (1.0, 5.0)]))
    events = (
        FaultEvent(kind="blackout", at_s=0.2, blackout_s=0.3),
        FaultEvent(kind="dropped", at_s=0.7, burst_s=0.5, drop_probability=0.5),
        FaultEvent(kind="corrupt_nan", at_s=1.4, burst_s=0.3, nan_fraction=0.3, nan_rows=5),
        FaultEvent(kind="stale", at_s=1.9, burst_s=0.3),
    )
    rig = Rig(FaultsConfig(events=events), b, (3.0, 3.0, 0.0), kinect=KinectConfig())
    ref = Rig(FaultsConfig(), b, (3.0, 3.0, 0.0), kinect=KinectConfig(), injector=False)
    got, want = [], []
    for _ in range(75):
        got.append(rig.tick((0.0, 0.0, 0.6))[0])
        want.append(ref.tick((0.0, 0.0, 0.6))[0])
    spans = {e["kind"]: (e["t_start"], e["t_end"]) for e in rig.faults.events}
    assert all(e["t_end"] is not None for e in rig.faults.events)

    def kind_at(t: float) -> str | None:
        return next((k for k, (a, z) in spans.items() if a < t <= z + 1e-9), None)

    counts: dict[str | None, int] = {}
    dropped = 0
    for g, w in zip(got, want, strict=True):
        k = kind_at(g.t)
        counts[k] = counts.get(k, 0) + 1
        assert np.array_equal(g.pose, w.pose) and np.array_equal(g.increment, w.increment)
        if k is None:
            assert g.depth is w.depth or np.array_equal(g.depth, w.depth)
        elif k == "blackout":
            assert g.depth.shape == w.depth.shape and not g.depth.any() and np.count_nonzero(w.depth) > 1000
        elif k == "dropped":
            if g.depth is None:
                dropped += 1
            else:
                assert np.array_equal(g.depth, w.depth)
        elif k == "corrupt_nan":
            nan = np.isnan(g.depth)
            rows = nan.all(axis=1)
            assert rows.sum() >= 5
            assert nan[~rows].mean() == pytest.approx(0.3, abs=0.01)
            assert np.array_equal(g.depth[~nan], w.depth[~nan])
        elif k == "stale":
            last_good = min(want, key=lambda x: abs(x.t - spans["stale"][0]))  # the frame before the burst
            assert np.array_equal(g.depth, last_good.depth) and not np.array_equal(g.depth, w.depth)
    # Each burst covers its duration in frames (30 Hz).
    assert counts == {"blackout": 9, "dropped": 15, "corrupt_nan": 9, "stale": 9, None: 75 - 42}
    assert 3 <= dropped <= 12
    rig.close()
    ref.close()


# --------------------------------------------------------------------------- tilt


def _rx(a: float) -> np.ndarray:
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


def _ry(a: float) -> np.ndarray:
    return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])


def _floor_depth(rows: np.ndarray, u: float, intr: CameraIntrinsics, height: float, pitch_down: float, dpitch: float, droll: float) -> np.ndarray:
    """Planar depth of the floor seen by pixels (u, rows) of a camera ``height`` above it,
    pitched ``pitch_down`` and then tilted (pitch, roll about the robot's y and x axes)."""
    level = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # optical z forward, x right, y down
    r = _ry(dpitch) @ _rx(droll) @ _ry(pitch_down) @ level
    rays = np.stack([np.full(len(rows), (u - intr.cx) / intr.fx), (rows - intr.cy) / intr.fy, np.ones(len(rows))])
    down = (r @ rays)[2]
    return np.where(down < 0, -height / np.where(down < 0, down, -1.0), np.inf)


@needs_gl
def test_tilt_renders_the_floor_from_the_tilted_camera() -> None:
    vm = box_room(30.0, 30.0)
    b = Building(vm, _line_graph([(5.0, 5.0), (25.0, 5.0), (25.0, 25.0), (5.0, 25.0)]))
    kinect = KinectConfig()
    tilt = FaultEvent(kind="tilt", at_s=0.0, tilt_deg=6.0)
    rig = Rig(FaultsConfig(events=(tilt,)), b, (15.0, 15.0, 0.7), kinect=kinect)
    intr, mount = kinect.intrinsics, kinect.mount
    u = 320
    rows = np.arange(intr.height)
    nominal = rig.camera.render_clean(rig.world.data)[:, u].copy()
    rig.faults.before_step(0.0, 0.0, None)
    tilted = rig.camera.render_clean(rig.world.data)[:, u].copy()
    ev = rig.faults.events[0]
    dp, dr = math.radians(ev["pitch_down_deg"]), math.radians(ev["roll_deg"])
    assert math.hypot(dp, dr) == pytest.approx(math.radians(6.0), abs=1e-12)
    for depth, p, r in ((nominal, 0.0, 0.0), (tilted, dp, dr)):
        want = _floor_depth(rows, u, intr, mount.height_m, mount.pitch_down_rad, p, r)
        seen = (want > 1.0) & (want < 4.5)
        assert seen.sum() > 100
        assert np.abs(depth[seen] - want[seen]).max() < 0.01
    # The tilt is what the frame shows: the nominal closed form no longer fits.
    want0 = _floor_depth(rows, u, intr, mount.height_m, mount.pitch_down_rad, 0.0, 0.0)
    both = (want0 < 4.5) & (tilted > 0)
    assert np.abs(tilted[both] - want0[both]).max() > 0.1
    # Persistent: later ticks keep the tilted camera; the robot stack's mount is unchanged.
    rig.tick()
    assert rig.faults.active == ["tilt"] and rig.world.mount == mount
    rig.close()


# --------------------------------------------------------------------------- crowd, blockage


def test_crowd_appears_around_the_robot_and_leaves_afterwards() -> None:
    b = corridor_loop()
    crowd = FaultEvent(kind="crowd", at_s=0.0, crowd_size=10, crowd_s=3.0)
    rig = Rig(FaultsConfig(events=(crowd,)), b, (22.5, 12.0, 1.57), seed=2)
    idx = rig.faults.crowd.members
    assert len(idx) == 10
    robot = np.array([22.5, 12.0])
    node_gap = float(np.hypot(*(b.navgraph.node_xy() - robot).T).min())
    for k in range(90):
        rig.tick()
        pos = rig.world.people.positions()[idx, :2]
        d = np.hypot(*(pos - robot).T)
        assert d.max() <= 8.0 + node_gap + 1.0, (k, d.max())  # a person steps up to 0.95 m aside
        if k == 0:
            assert d.min() >= RADIUS + 0.22 + 0.5 - 0.05
            assert rig.faults.events[0]["people"] == 10
    rig.tick()
    assert rig.faults.active == [] and rig.faults.events[0]["t_end"] == pytest.approx(3.0, abs=0.04)
    # They walk away and are parked once out of the camera's range.
    for _ in range(30 * 40):
        rig.tick()
        if not rig.faults.crowd.leaving:
            break
    pos = rig.world.people.positions()[idx, :2]
    assert np.allclose(pos, PARK_XY, atol=2.0)
    rig.close()


def _blockage_rig(kinect: KinectConfig, blockage_s: float = 0.0):
    b = corridor_loop()
    g = b.navgraph
    start = np.array([12.0, 6.3, 0.0])
    cfg = FaultsConfig(events=(FaultEvent(kind="blockage", at_s=0.0, blockage_s=blockage_s),))
    return Rig(cfg, b, start, kinect=kinect, seed=4), g.nearest_node(34.0, 6.3)


def test_blockage_is_placed_across_the_way_to_the_waypoint_where_another_route_remains() -> None:
    rig, goal = _blockage_rig(TINY, blockage_s=0.5)
    rig.tick(goal=goal)
    ev = rig.faults.events[0]
    assert "skipped" not in ev, ev
    w = ev["where"]
    a, z = np.array(w["ends"])
    # Across the corridor (bottom corridor: walls at about y = 5.2 and 7.4), 4-8 m ahead.
    assert abs(a[0] - z[0]) < 1e-6 and 16.0 - 0.3 <= a[0] <= 20.0 + 0.3
    walls = np.asarray(rig.building.vectormap.segments)
    assert point_segment_distance(a, walls).min() < 1e-6 and point_segment_distance(z, walls).min() < 1e-6
    assert 1.5 < w["width_m"] < 3.0 and w["panels"] == math.ceil(w["width_m"] / 0.5)
    # The way is cut, another way to the waypoint remains (independently: the graph without the cut edges).
    g = rig.building.navgraph
    cut = {tuple(sorted(e)) for e in w["cut_edges"]}
    assert cut
    kept = tuple(e for e in g.edges if tuple(sorted((e.s0_id, e.s1_id))) not in cut)
    other = astar(NavGraph(g.nodes, kept), g.nearest_node(12.0, 6.3), g.nearest_node(34.0, 6.3))
    pts = path_points(g, other)
    assert np.hypot(*np.diff(pts, axis=0).T).sum() > 30.0  # round the loop, not 22 m straight on
    # The panels stand in the world (the robot collides with them), then go back to the park.
    bodies = rig.faults.blockage.bodies()
    xy = rig.world.model.body_pos[bodies, :2]
    used = xy[np.hypot(*(xy - np.array(w["centre"])).T) < 1.5]
    assert len(used) == w["panels"]
    # Wall to wall, no gap and nothing through a wall: the panels' spans along the line
    # cover it and end on it.
    u = (z - a) / w["width_m"]
    along = np.sort((used - a) @ u)
    assert np.allclose((used - a) @ np.array([-u[1], u[0]]), 0.0, atol=1e-9)
    assert along[0] - 0.25 == pytest.approx(0.0, abs=1e-9) and along[-1] + 0.25 == pytest.approx(w["width_m"], abs=1e-9)
    assert np.all(np.diff(along) <= 0.5 + 1e-9)
    for _ in range(20):
        rig.tick(goal=goal)
    assert ev["t_end"] == pytest.approx(0.5, abs=0.04)
    assert np.all(np.hypot(*(rig.world.model.body_pos[bodies, :2] - PARK_XY).T) > 40.0)
    rig.close()


@needs_gl
def test_blockage_shows_in_the_depth_frame() -> None:
    """The slab across the corridor ahead, rendered: the centre column above the floor
    sees a plane at the slab's face (closed form), where it saw farther before."""
    kinect = KinectConfig(render_far_m=20.0)
    rig, goal = _blockage_rig(kinect)
    before = rig.camera.render_clean(rig.world.data)[:, 320].copy()
    rig.faults.before_step(0.0, 0.0, goal)
    after = rig.camera.render_clean(rig.world.data)[:, 320].copy()
    w = rig.faults.events[0]["where"]
    face_x = w["centre"][0] - 0.5 * rig.faults.cfg.blockage_depth_m
    intr, mount = kinect.intrinsics, kinect.mount
    cam = np.array([12.0 + mount.forward_m, 6.3, mount.height_m])
    level = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    r = _ry(mount.pitch_down_rad) @ level
    rows = np.arange(intr.height)
    rays = r @ np.stack([np.full(intr.height, (320 - intr.cx) / intr.fx), (rows - intr.cy) / intr.fy, np.ones(intr.height)])
    z = (face_x - cam[0]) / rays[0]
    hit_h = cam[2] + z * rays[2]
    on_slab = (hit_h > 0.3) & (hit_h < rig.faults.cfg.blockage_height_m - 0.1)
    assert on_slab.sum() > 30
    assert np.abs(after[on_slab] - z[on_slab]).max() < 0.02
    assert np.all((before[on_slab] == 0) | (before[on_slab] > z[on_slab] + 0.5))
    rig.close()


def test_a_blockage_waits_for_a_place_and_is_skipped_after_the_wait() -> None:
    """Due without a waypoint, it waits; placed once there is one, with when it was due; a
    second one that finds no place while the robot drives 50 m is recorded as skipped."""
    rig, goal = _blockage_rig(TINY)
    for _ in range(3):
        rig.tick(goal=None)
    assert rig.faults.events == [] and rig.faults.active == []
    while not rig.faults.events:
        rig.tick(goal=goal)
    ev = rig.faults.events[0]
    # It looks again every 0.5 s.
    assert "where" in ev and ev["due_t"] == 0.0 and ev["t_start"] == pytest.approx(0.5, abs=1e-6) and rig.faults.active == ["blockage"]
    rig.close()

    rig, _ = _blockage_rig(TINY)
    rig.tick(goal=None)
    rig.distance_m = 49.0
    rig.tick(goal=None)
    assert rig.faults.events == []
    rig.distance_m = 51.0
    for _ in range(16):  # it looks every 0.5 s
        rig.tick(goal=None)
    ev = rig.faults.events[0]
    assert ev["t_end"] == ev["t_start"] and "no corridor" in ev["skipped"] and rig.faults.active == []
    assert ev["due_distance_m"] == 0.0 and ev["distance_m"] >= 51.0
    rig.close()


def test_the_injector_needs_the_fault_actors_in_the_world() -> None:
    b = corridor_loop()
    cfg = FaultsConfig(every_m=100.0)
    world = build_world(b.vectormap, start_pose=(12.0, 6.3, 0.0))
    odo = Odometry(OdometryConfig(), np.random.default_rng(0), np.array([12.0, 6.3, 0.0]))
    with pytest.raises(ValueError, match="fault_actors"):
        FaultInjector(cfg, world, b, fault_rng(0), odo, RADIUS)
