"""The world as the faults read and move it (:class:`FaultScene`).

Every fault kind that changes the world asks the same questions of it: where the robot
truly is, where furniture and people stand, whether the robot fits at a place, how far
the navigation graph's nodes are. Those answers, and the one way the faults move the
robot (a teleport the odometry does not see), live here, apart from the faults' own
bookkeeping in :mod:`sim.simulator.faults`.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from autonomy.common.geometry import crosses_any
from autonomy.maps.planner import adjacency, dijkstra
from sim.simulator.actors import furniture_body
from sim.simulator.building import Building
from sim.simulator.robot import Odometry
from sim.simulator.world import World


class FaultScene:
    """The world, the building and the odometry a run's faults act on, with the robot's
    radius: the true pose, the actors' footprints, fit tests and graph distances."""

    def __init__(self, world: World, building: Building, odometry: Odometry, robot_radius_m: float) -> None:
        self.world = world
        self.building = building
        self.odometry = odometry
        self.robot_radius_m = float(robot_radius_m)
        self.walls = np.ascontiguousarray(building.vectormap.segments, dtype=np.float64).reshape(-1, 4)
        """The building's walls (N, 4)."""
        model = world.model
        self.furniture_bodies = np.array(
            [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, furniture_body(i)) for i in range(len(world.furniture))], dtype=np.int64
        )
        """MuJoCo body id of each furniture piece (the world's order)."""
        self.furniture_half = np.array([0.5 * math.hypot(f.dims[0], f.dims[1]) for f in world.furniture])
        """Footprint radius (half diagonal) of each furniture piece."""
        self._adj = None

    def pose(self) -> np.ndarray:
        """The robot's true pose (x, y, theta)."""
        return self.world.robot.pose(self.world.data)

    def teleport(self, pose: np.ndarray) -> None:
        """Move the robot (stopped) without the odometry seeing it."""
        w = self.world
        w.robot.set_pose(w.data, (float(pose[0]), float(pose[1]), float(pose[2])))
        mujoco.mj_forward(w.model, w.data)
        self.odometry.rebase(w.robot.pose(w.data))

    def actors(self) -> tuple[np.ndarray, np.ndarray]:
        """Centres (n, 2) and footprint radii (n,) of the furniture and the people where they are now."""
        model = self.world.model
        f_xy = model.body_pos[self.furniture_bodies, :2] if len(self.furniture_bodies) else np.zeros((0, 2))
        people = self.world.people
        p_xy = people.positions()[:, :2] if len(people.people) else np.zeros((0, 2))
        p_r = np.array([p.radius_m for p in people.people])
        return np.vstack([f_xy, p_xy]), np.concatenate([self.furniture_half, p_r])

    def clear_of_actors(self, xy: np.ndarray, gap_m: float) -> bool:
        """Whether the robot at ``xy`` keeps ``gap_m`` (body to body) from every furniture piece and person."""
        centres, radii = self.actors()
        if not len(centres):
            return True
        return bool(np.all(np.hypot(*(centres - xy).T) >= self.robot_radius_m + radii + gap_m))

    def fits(self, start: np.ndarray, xy: np.ndarray, clearance_m: float) -> bool:
        """Whether the robot fits at ``xy`` (the building's free space with ``clearance_m``
        beyond its radius, as far from furniture and people) and gets there from
        ``start`` through no wall."""
        fs = self.building.free_space(self.robot_radius_m)
        i, j = fs.cell_of(xy)
        if fs.region[i, j] < 0 or fs.dist[i, j] - fs.error_m < self.robot_radius_m + clearance_m:
            return False
        if len(self.walls) and crosses_any(start, xy, self.walls):
            return False
        return self.clear_of_actors(xy, clearance_m)

    def graph_distance(self, xy: np.ndarray) -> np.ndarray:
        """Graph distance of every node (node order) from the node nearest ``xy``."""
        graph = self.building.navgraph
        if self._adj is None:
            self._adj = adjacency(graph)
        k = graph.index_of(graph.nearest_node(float(xy[0]), float(xy[1])))
        return dijkstra(self._adj, {k: float(np.hypot(*(graph.node_xy()[k] - xy)))})[0]
