"""Your own stack in the loop: the Driver protocol through a scenario's [driver] table,
and the worked example."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

from autonomy.common.errors import InputError
from autonomy.stack.driver import Driver, DriverCommand, DriverFrame, DriverGoal, DriverSetup
from sim.cli import main
from sim.experiments.kinds import RunCrashed
from sim.experiments.runner import run_scenario
from sim.scenario import SCENARIOS_DIR, load_scenario
from tests.helpers import GL, err_line

ROOT = Path(__file__).resolve().parents[2]

#: A driver module written beside the scenario: it records what it was handed.
DRIVER = '''
import math
import numpy as np
from autonomy.common.geometry import compose_pose
from autonomy.stack.driver import DriverCommand

SEEN = []

class Straight:
    """Turns to the goal on its odometry and drives at it; reports its dead reckoning."""
    def __init__(self, setup):
        self.setup, self.pose, self.goal = setup, None, None
        SEEN.append(("setup", setup))
    def reset(self, start_pose):
        SEEN.append(("reset", start_pose))
        self.pose = np.array(start_pose, dtype=float)
    def relocalize(self, pose):
        SEEN.append(("relocalize", pose))
        self.pose = np.array(pose, dtype=float)
    def set_goal(self, goal):
        SEEN.append(("goal", goal))
        self.goal = goal
    def step(self, frame):
        SEEN.append(("frame", frame))
        if frame.odometry is not None:
            self.pose = compose_pose(self.pose, frame.odometry)
        d = self.goal.xy - self.pose[:2]
        if math.hypot(*d) < 0.3:
            return DriverCommand(np.zeros(3), {estimate}, arrived=True)
        b = math.remainder(math.atan2(d[1], d[0]) - self.pose[2], math.tau)
        v = 0.4 if abs(b) < 0.3 else 0.0
        return DriverCommand(np.array([v, 0.0, 1.5 * b]), {estimate})

def make(setup):
    return Straight(setup)

def make_nothing(setup):
    return object()

def make_raising(setup):
    raise RuntimeError("no such robot")

class NeedsStart(Straight):
    def reset(self, start_pose):
        raise ValueError("needs the start pose")

def make_needs_start(setup):
    return NeedsStart(setup)

def make_bad(setup):
    class Bad(Straight):
        def step(self, frame):
            return DriverCommand(np.array([float("nan"), 0.0, 0.0]))
    return Bad(setup)
'''

SCENARIO = """
name = "own"
seed = 5
[map]
name = "small_floor"
[mission]
waypoints = {waypoints}
max_duration_s = {duration}
[report]
figures = {figures}
[driver]
factory = "{factory}"
"""


def write(tmp_path: Path, factory: str = "driver.py:make", estimate: str = "self.pose.copy()", duration: float = 40.0,
          figures: bool = False, waypoints: str = "[]") -> Path:
    (tmp_path / "driver.py").write_text(DRIVER.replace("{estimate}", estimate), encoding="utf-8")
    p = tmp_path / "own.toml"
    p.write_text(SCENARIO.format(factory=factory, duration=duration, figures=str(figures).lower(), waypoints=waypoints), encoding="utf-8")
    return p


def seen(tmp_path: Path) -> list:
    from sim.experiments.driver_stack import load_factory

    return load_factory("driver.py:make", tmp_path, "t").__globals__["SEEN"]


def test_the_protocol_is_checkable() -> None:
    class Mine:
        def reset(self, start_pose): ...
        def set_goal(self, goal): ...
        def step(self, frame): return DriverCommand(np.zeros(3))

    assert isinstance(Mine(), Driver) and not isinstance(object(), Driver)


@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_a_driver_drives_the_mission_with_frames_and_odometry_but_never_the_truth(tmp_path: Path) -> None:
    p = write(tmp_path, duration=30.0)
    scn = load_scenario(p)
    rep = run_scenario(scn, tmp_path / "out", progress=False)
    log = seen(tmp_path)
    kinds = [k for k, _ in log]
    assert kinds[0] == "setup" and kinds[1] == "reset"
    setup = log[0][1]
    assert isinstance(setup, DriverSetup) and setup.robot_radius_m == scn.robot.radius_m and setup.frame_rate_hz == 30.0
    start = log[1][1]
    assert start is not None and np.allclose(start, rep_start(tmp_path / "out"))
    goals = [g for k, g in log if k == "goal"]
    frames = [f for k, f in log if k == "frame"]
    assert goals and all(isinstance(g, DriverGoal) for g in goals)
    # Each goal is its node's place on the graph.
    graph = setup.navgraph
    assert all(np.allclose(g.xy, graph.node_xy()[graph.index_of(g.node)]) for g in goals)
    # Every frame is a depth image and an odometry increment, 30 a second; no pose.
    assert all(isinstance(f, DriverFrame) for f in frames) and set(vars(frames[0])) == {"t", "depth", "odometry"}
    assert frames[1].odometry is not None and frames[5].depth.shape == (480, 640) and frames[5].depth.dtype == np.float32
    assert np.allclose(np.diff([f.t for f in frames[1:50]]), 1 / 30, atol=1e-6)
    m = rep["metrics"]
    # It drove, reached waypoints it declared (checked against the truth), and its dead
    # reckoning was measured against the truth.
    assert m["distance_m"] > 3.0 and m["waypoints_reached"] >= 1, m
    assert "loc_error_p95_m" in m and m["loc_error_p95_m"] < 1.0
    assert rep["expect"]["passed"] is True


@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_a_driver_without_a_belief_has_no_localization_figures(tmp_path: Path) -> None:
    rep = run_scenario(load_scenario(write(tmp_path, estimate="None", duration=3.0)), tmp_path / "out", progress=False)
    assert "loc_error_p95_m" not in rep["metrics"] and rep["metrics"]["frames"] == 90


@pytest.mark.parametrize(
    ("factory", "pattern"),
    [
        ("nowhere.py:make", r"own\.toml: key 'driver\.factory': file not found: .*nowhere\.py"),
        ("driver.py:absent", r"own\.toml: key 'driver\.factory': driver\.py has no function 'absent'"),
        ("no_such_pkg.mod:make", r"own\.toml: key 'driver\.factory': no module 'no_such_pkg'"),
        ("make", r"own\.toml: key 'driver\.factory' expected 'package\.module:function' or 'file\.py:function'"),
    ],
)
def test_a_factory_that_cannot_be_found_is_one_line_at_load(tmp_path: Path, capsys, factory: str, pattern: str) -> None:
    p = write(tmp_path, factory=factory)
    assert main(["run", str(p), "--out", str(tmp_path / "o")]) == 2
    line = err_line(capsys)
    assert line.startswith("depthnav: error: ") and __import__("re").search(pattern, line), line


def test_a_driver_gets_no_truth_so_the_truth_follower_is_refused(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="a \\[driver\\] of your own gets no truth"):
        load_scenario(write(tmp_path), ["mission.follower=\"ground_truth\""])


@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_a_factory_that_returns_no_driver_is_one_line(tmp_path: Path, capsys) -> None:
    p = write(tmp_path, factory="driver.py:make_nothing")
    assert main(["run", str(p), "--out", str(tmp_path / "o")]) == 2
    assert "returned object, which lacks reset, set_goal or step" in err_line(capsys)


@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
@pytest.mark.parametrize(
    ("factory", "needle"),
    [("driver.py:make_raising", "'driver.py:make_raising' raised RuntimeError: no such robot"),
     ("driver.py:make_needs_start", "'driver.py:make_needs_start': its reset raised ValueError: needs the start pose")],
)
def test_a_driver_that_fails_before_the_run_is_one_line(tmp_path: Path, capsys, factory: str, needle: str) -> None:
    p = write(tmp_path, factory=factory)
    assert main(["run", str(p), "--out", str(tmp_path / "o")]) == 2
    line = err_line(capsys)
    assert needle in line, line


@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_a_driver_commanding_nan_stops_the_run_naming_the_driver(tmp_path: Path) -> None:
    p = write(tmp_path, factory="driver.py:make_bad", duration=3.0)
    with pytest.raises(RunCrashed, match=r"ValueError: the driver of 'driver\.py:make_bad' commanded velocity"):
        run_scenario(load_scenario(p), tmp_path / "o", progress=False)
    assert (tmp_path / "o" / "report.json").is_file()


def rep_start(out: Path) -> np.ndarray:
    """The run's true start pose (the first row of its TUM trajectory)."""
    row = np.loadtxt(out / "trajectory_truth.tum")[0]
    return np.array([row[1], row[2], 2 * math.atan2(row[6], row[7])])


# --------------------------------------------------------------------------- the example


def example():
    spec = importlib.util.spec_from_file_location("reactive_driver_example", ROOT / "examples" / "reactive_driver.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_examples_free_lengths_match_brute_force() -> None:
    mod = example()
    rng = np.random.default_rng(0)
    pts = rng.uniform(-3, 3, (200, 2))
    pts = pts[np.hypot(*pts.T) > 0.4]  # nothing inside the robot
    angles = np.radians(np.arange(-40, 41, 5.0))
    got = mod.free_lengths(pts, angles, 0.4)
    for a, g in zip(angles, got, strict=True):
        # Brute force: march the disc along the direction in 1 mm steps.
        u = np.array([math.cos(a), math.sin(a)])
        s = 0.0
        while s < 10 and np.min(np.hypot(*(pts - s * u).T)) >= 0.4:
            s += 0.001
        assert (s >= 10 and (math.isinf(g) or g > 9.9)) or abs(s - g) < 0.0015, (a, s, g)
    assert np.isinf(mod.free_lengths(np.zeros((0, 2)), angles, 0.4)).all()


@pytest.mark.slow
@pytest.mark.skipif(not GL, reason="no EGL/OSMesa context on this machine")
def test_the_example_driver_runs_the_demo_with_report_figures_and_recording(tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert main(["run", str(SCENARIOS_DIR / "demo_own_driver.toml"), "--out", str(out), "--rrd", str(out / "own.rrd"),
                 "--set", "mission.target_distance_m=25"]) == 0
    rep = json.loads((out / "report.json").read_text())
    m = rep["metrics"]
    assert rep["interrupted"] is False and rep["error"] is None
    assert m["distance_m"] > 25 and m["waypoints_reached"] >= 1 and m["loc_error_p95_m"] < 0.3, m
    assert (out / "trajectory.png").stat().st_size > 1000 and (out / "own.rrd").stat().st_size > 10_000
    assert rep["config"]["driver"]["factory"] == "../examples/reactive_driver.py:make"
