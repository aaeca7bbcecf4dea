"""A user's :class:`autonomy.stack.driver.Driver` in the closed loop of a mission run.

:class:`DriverStack` gives the loop what it reads from the project's
:class:`autonomy.stack.RobotStack` (its ``reset``, ``set_goal``, ``step`` and
``redecide``, each returning a :class:`autonomy.stack.StackOutput`), made from the
driver's commands, so that the runner, faults, reports, figures, recordings,
expectations and sweeps need no second path. What only the project's stack has (FSPF's
points, CGR's particles, the health monitor) is empty. The mission's leg budget is
measured on the graph route from where each leg starts, as for the project's stack.
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import compose_pose
from autonomy.maps.navgraph import NavGraph
from autonomy.maps.planner import NoPathError, astar
from autonomy.navigation.config import NavCommand, NavigatorConfig
from autonomy.navigation.plan import Plan
from autonomy.stack import StackOutput
from autonomy.stack.driver import Driver, DriverCommand, DriverFrame, DriverGoal, DriverSetup
from autonomy.stack.output import PlanView
from autonomy.stack.state import empty_perception

#: The frame faults the report counts (none for a driver: it sees every frame as it comes).
_NO_REJECTS = {"dropped": 0, "stale": 0, "invalid": 0, "corrupt": 0}


def load_factory(spec: str, base_dir: str | Path, source: str) -> Callable[[DriverSetup], Driver]:
    """The callable ``spec`` names: ``package.module:function`` (imported), or
    ``path/file.py:function`` (a file, relative to ``base_dir``); an InputError naming
    ``source``'s ``driver.factory`` when it cannot be found."""
    where, _, name = spec.rpartition(":")
    key = f"{source}: key 'driver.factory'"
    if not where or not name.isidentifier():
        raise InputError(f"{key} expected 'package.module:function' or 'file.py:function', got {spec!r}")
    if where.endswith(".py"):
        path = Path(where) if Path(where).is_absolute() else Path(base_dir) / where
        if not path.is_file():
            raise InputError(f"{key}: file not found: {path}")
        mod_name = f"depthnav_driver_{abs(hash(str(path.resolve())))}"
        module = sys.modules.get(mod_name)
        if module is None:
            spec_ = importlib.util.spec_from_file_location(mod_name, path)
            assert spec_ is not None and spec_.loader is not None
            module = importlib.util.module_from_spec(spec_)
            sys.modules[mod_name] = module
            spec_.loader.exec_module(module)
    else:
        try:
            module = importlib.import_module(where)
        except ModuleNotFoundError as exc:
            raise InputError(f"{key}: no module {exc.name!r} (is it installed, or on PYTHONPATH?)") from None
    factory = getattr(module, name, None)
    if not callable(factory):
        raise InputError(f"{key}: {where} has no function {name!r}")
    return factory


class DriverStack:
    """The loop's robot stack made from a :class:`Driver` (see the module docstring)."""

    def __init__(self, driver: Driver, setup: DriverSetup, navigator: NavigatorConfig, factory: str) -> None:
        if not isinstance(driver, Driver):
            raise InputError(f"driver.factory {factory!r}: returned {type(driver).__name__}, which lacks reset, set_goal or step (autonomy.stack.driver.Driver)")
        self.driver, self.setup, self.navigator_cfg, self.factory = driver, setup, navigator, factory
        self.graph: NavGraph = setup.navgraph
        self.odometry = np.zeros(3)
        """Dead reckoning from the start (or the origin when it is unknown)."""
        self.command = DriverCommand(np.zeros(3))
        self.plan = Plan(navigator, setup.robot_radius_m)
        self.timings_s = {"fspf": 0.0, "obstacles": 0.0, "localization": 0.0, "navigation": 0.0}

    def prepare_recovery(self) -> None:
        """Nothing to prepare: the driver's recovery is its own."""

    def reset(self, pose: np.ndarray | None) -> StackOutput:
        self.odometry = np.zeros(3) if pose is None else np.asarray(pose, dtype=np.float64).copy()
        try:
            self.driver.reset(None if pose is None else self.odometry.copy())
        except Exception as exc:  # before the run: named, in one line
            raise InputError(f"driver.factory {self.factory!r}: its reset raised {type(exc).__name__}: {exc}") from None
        self.command = DriverCommand(np.zeros(3), None if pose is None else self.odometry.copy())
        return self._output(self.odometry)

    def set_goal(self, node_id: int, t: float, pose: np.ndarray | None = None) -> PlanView:
        """Hand the driver the leg's goal; the leg's route on the graph (from the node
        nearest ``pose``) measures its budget."""
        at = self.odometry if pose is None else np.asarray(pose, dtype=np.float64)
        xy = self.graph.node_xy()
        goal_xy = xy[self.graph.index_of(int(node_id))].astype(np.float64)
        start = self.graph.nearest_node(float(at[0]), float(at[1]))
        try:
            nodes = astar(self.graph, start, int(node_id))
        except NoPathError:
            nodes = [int(node_id)]
        pts = np.vstack([np.asarray(at[:2], dtype=np.float64)[None, :], xy[[self.graph.index_of(n) for n in nodes]]])
        self.plan = Plan.along(self.navigator_cfg, self.setup.robot_radius_m, int(node_id), nodes, pts, [None] * (len(pts) - 1), {}, {})
        self.driver.set_goal(DriverGoal(int(node_id), goal_xy.copy(), float(t)))
        view = PlanView(self.plan, None, float(self.plan.cum[-1]), 0, 0, 0)
        return view

    def step(
        self, depth: np.ndarray | None, increment: np.ndarray | None, t: float, pose: np.ndarray | None = None, *,
        localize: bool = True, operator: Callable[[StackOutput], np.ndarray | None] | None = None, correspondences: bool = False,
        **_: object,
    ) -> StackOutput:
        """One frame to the driver (the truth ``pose`` is never handed on); the
        ``operator``'s truth reset, if any, goes to the driver's ``relocalize(pose)`` when
        it has one, for the next frame."""
        if increment is not None:
            self.odometry = compose_pose(self.odometry, np.asarray(increment, dtype=np.float64))
        t0 = time.perf_counter()
        cmd = self.driver.step(DriverFrame(float(t), depth, None if increment is None else np.asarray(increment, dtype=np.float64).copy()))
        self.timings_s["navigation"] = time.perf_counter() - t0
        self.command = _checked(cmd, self.factory)
        out = self._output(pose)
        if operator is not None and out.localizing:
            reset_to = operator(out)
            relocalize = getattr(self.driver, "relocalize", None)
            if reset_to is not None and callable(relocalize):
                relocalize(np.asarray(reset_to, dtype=np.float64).copy())
        return out

    def redecide(self, t: float, pose: np.ndarray | None = None) -> StackOutput:
        """The last command again (the driver decides on the next frame with the new goal)."""
        self.command = DriverCommand(np.zeros(3), self.command.estimate)
        return self._output(pose)

    def _output(self, pose: np.ndarray | None) -> StackOutput:
        c = self.command
        est = c.estimate
        at = (est if est is not None else self.odometry) if pose is None else pose
        return StackOutput(
            command=NavCommand(np.asarray(c.velocity, dtype=np.float64).copy(), "arrived" if c.arrived else "driving"),
            estimate=(self.odometry if est is None else est).copy(),
            spread=(0.0, 0.0),
            perception=empty_perception(),
            timings_s=dict(self.timings_s),
            plan=PlanView(self.plan, np.array(at[:2], dtype=np.float64), math.nan, 0, 0, 0),
            localizing=est is not None,
            relocalizing=False,
            health_state="ok",
            health_sample=None,
            events=(),
            frame_fault="",
            frames_rejected=dict(_NO_REJECTS),
            cgr_stats=None,
            correction=None,
            odometry=self.odometry.copy(),
            particles=None,
            refinement=None,
            last_search=None,
            correspondences=None,
        )


def _checked(cmd: object, factory: str) -> DriverCommand:
    """A driver's command, checked: a DriverCommand with a finite 3-vector velocity and,
    if given, a finite 3-vector estimate (a driver's bug is named, not a NaN in the physics)."""
    if not isinstance(cmd, DriverCommand):
        raise TypeError(f"the driver of {factory!r} returned {type(cmd).__name__} from step, expected a DriverCommand")
    v = np.asarray(cmd.velocity, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"the driver of {factory!r} commanded velocity {cmd.velocity!r}, expected 3 finite numbers (vx, vy, omega)")
    if cmd.estimate is not None:
        e = np.asarray(cmd.estimate, dtype=np.float64)
        if e.shape != (3,) or not np.all(np.isfinite(e)):
            raise ValueError(f"the driver of {factory!r} reported estimate {cmd.estimate!r}, expected 3 finite numbers (x, y, theta)")
        return DriverCommand(v, e, bool(cmd.arrived))
    return DriverCommand(v, None, bool(cmd.arrived))
