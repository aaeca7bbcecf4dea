"""A worked example of your own stack in the loop: a reactive controller on the scan.

It keeps this project's perception and localization (FSPF and CGR, through
:class:`autonomy.stack.RobotStack` built with ``navigate = false``) and replaces the
navigation: it plans a route of graph nodes with A*, and every frame steers towards the
next node along the free direction of the frame's obstacle scan nearest to it (a
one-frame vector-field-histogram rule, no memory). Run it on the demo with

    depthnav run scenarios/demo_own_driver.toml

whose ``[driver]`` table names ``make`` below; or from Python, with any scenario:
``--set 'driver.factory="examples/reactive_driver.py:make"'`` (a path relative to the
scenario file, or ``package.module:function`` for an installed package).
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.maps.planner import NoPathError, astar
from autonomy.stack import RobotStack, StackConfig
from autonomy.stack.driver import DriverCommand, DriverFrame, DriverGoal, DriverSetup

#: Candidate directions (robot frame), within the camera's view: it sees nothing to the sides.
CANDIDATES_RAD = np.radians(np.arange(-25.0, 25.1, 2.5))
#: Extra clearance on each side of the robot's body, metres.
MARGIN_M = 0.12
#: A direction must be free for this far to drive along it, metres.
MIN_FREE_M = 0.6
#: A node of the route counts as passed within this distance (the goal: ARRIVAL_M).
PASS_M = 0.8
ARRIVAL_M = 0.3


def free_lengths(obstacles: np.ndarray, angles: np.ndarray, radius_m: float) -> np.ndarray:
    """For each direction, how far the robot's disc (``radius_m``) can move along it before
    touching one of the obstacle points (robot frame, (n, 2)); inf when nothing is in the way."""
    if len(obstacles) == 0:
        return np.full(len(angles), np.inf)
    u = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (k, 2)
    along = obstacles @ u.T  # (n, k)
    across = np.abs(obstacles[:, 0:1] * u[:, 1] - obstacles[:, 1:2] * u[:, 0])
    hit = (along > 0) & (across < radius_m)
    # The disc touches a point at along - sqrt(r^2 - across^2) (closed form).
    reach = np.where(hit, along - np.sqrt(np.maximum(radius_m**2 - across**2, 0.0)), np.inf)
    return np.maximum(reach.min(axis=0), 0.0)


class ReactiveDriver:
    """CGR for the belief, A* on the graph for the route, a reactive rule for the motion."""

    def __init__(self, setup: DriverSetup) -> None:
        self.setup = setup
        cfg = StackConfig(camera=setup.camera, navigate=False)
        self.stack = RobotStack(setup.vectormap, None, cfg, rng=np.random.default_rng(setup.seed), fspf_seed=setup.seed)
        self.route: list[np.ndarray] = []
        self.goal: DriverGoal | None = None
        self.frames = 0

    def reset(self, start_pose: np.ndarray | None) -> None:
        if start_pose is None:
            raise ValueError("reactive_driver: needs the start pose (localization.start_known = true)")
        self.stack.reset(start_pose)
        self.route, self.goal, self.frames = [], None, 0

    def relocalize(self, pose: np.ndarray) -> None:
        """The simulation's operator put the belief back at the truth (a truth reset)."""
        self.stack.relocalize(pose)

    def set_goal(self, goal: DriverGoal) -> None:
        g = self.setup.navgraph
        est = self.stack.state.pose
        start = g.nearest_node(float(est[0]), float(est[1]))
        try:
            nodes = astar(g, start, goal.node)
        except NoPathError:
            nodes = [goal.node]
        xy = g.node_xy()
        self.route = [xy[g.index_of(n)].astype(float) for n in nodes]
        self.goal = goal

    def step(self, frame: DriverFrame) -> DriverCommand:
        out = self.stack.step(frame.depth, frame.odometry, frame.t, localize=self.frames > 0)
        self.frames += 1
        pose = out.estimate
        if self.goal is None:
            return DriverCommand(np.zeros(3), pose)
        # Pass route nodes the robot is near; the last one is the goal.
        while len(self.route) > 1 and math.dist(pose[:2], self.route[0]) < PASS_M:
            self.route.pop(0)
        target = self.route[0]
        d = math.dist(pose[:2], target)
        if len(self.route) == 1 and d < ARRIVAL_M:
            return DriverCommand(np.zeros(3), pose, arrived=True)
        bearing = math.remainder(math.atan2(target[1] - pose[1], target[0] - pose[0]) - pose[2], math.tau)
        s = self.setup
        w = float(np.clip(1.5 * bearing, -s.max_angular_rad_s, s.max_angular_rad_s))
        if abs(bearing) > math.radians(35):
            return DriverCommand(np.array([0.0, 0.0, w]), pose)  # face the target first
        free = free_lengths(out.perception.obstacles, CANDIDATES_RAD, s.robot_radius_m + MARGIN_M)
        ok = free >= MIN_FREE_M
        if not ok.any():
            return DriverCommand(np.array([0.0, 0.0, math.copysign(0.6, bearing or 1.0)]), pose)  # blocked: look round
        score = np.where(ok, np.cos(CANDIDATES_RAD - bearing), -np.inf)
        k = int(np.argmax(score))
        heading, room = float(CANDIDATES_RAD[k]), float(free[k])
        speed = min(s.max_speed_mps, 0.5 * (room - 0.3), d) if math.isfinite(room) else min(s.max_speed_mps, d)
        speed = max(speed, 0.1)
        return DriverCommand(np.array([speed * math.cos(heading), speed * math.sin(heading), w]), pose)


def make(setup: DriverSetup) -> ReactiveDriver:
    """The factory a scenario's ``[driver] factory`` names."""
    return ReactiveDriver(setup)
