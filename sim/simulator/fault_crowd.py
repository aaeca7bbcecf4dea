"""The crowd fault's people (:class:`FaultCrowd`).

A crowd is people compiled into the world parked outside the building (see
:func:`sim.simulator.fault_config.fault_actors`), called in to walk graph routes near the
robot while the fault lasts, then sent away along graph edges clear of the robot and
parked again once out of the camera's range.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import point_segment_distance
from autonomy.maps.navgraph import NavGraph
from autonomy.maps.planner import astar, path_points
from sim.simulator.actors import Person, parked_person
from sim.simulator.building import random_people
from sim.simulator.fault_config import TIME_EPS_S, FaultParams
from sim.simulator.fault_scene import FaultScene

#: A crowd person appears this far beyond both radii from the robot.
CROWD_START_CLEARANCE_M = 0.5
#: Tries for a start point clear of the robot before a crowd person stays parked.
CROWD_START_TRIES = 20
#: A crowd walks away to a node this much farther (on the graph) than its radius ...
LEAVE_BEYOND_M = (4.0, 12.0)
#: ... on graph edges this far beyond the robot's radius from it ...
LEAVE_ROBOT_GAP_M = 0.6
#: ... and a leaving person is parked once this far from the robot (beyond the camera's range).
PARK_BEYOND_M = 6.0


class FaultCrowd:
    """The people a crowd fault uses (``members``: indices into the world's people) and
    those walking away after one (``leaving``)."""

    def __init__(self, scene: FaultScene, rng: np.random.Generator, members: list[int]) -> None:
        self.scene = scene
        self.rng = rng
        self.members = members
        """The world's people the crowd calls in (parked when not in use)."""
        self.leaving: dict[int, tuple[float, float]] = {}
        """Person index -> (time sent away, how long their walk out takes)."""

    def start(self, rec: dict, params: FaultParams, pose: np.ndarray) -> bool:
        """Call the crowd in on random graph routes within ``crowd_radius_m`` of the robot
        at ``pose``, each starting clear of it; False (recorded as skipped) when nobody could be."""
        graph = self.scene.building.navgraph
        dist = self.scene.graph_distance(pose[:2])
        ids = graph.node_ids()
        routes: tuple[Person, ...] = ()
        # Routes between nodes within half the radius keep every point of them within it.
        for r in (0.5 * params.crowd_radius_m, params.crowd_radius_m):
            nodes = ids[dist <= r]
            if len(nodes) >= 2:
                routes = random_people(graph, params.crowd_size, self.rng, nodes)
            if routes:
                break
        people = self.scene.world.people
        placed = 0
        for i, person in zip(self.members, routes, strict=False):
            self.leaving.pop(i, None)
            length = float(np.sum(np.hypot(*np.diff(np.asarray(person.route), axis=0).T)))
            for _ in range(CROWD_START_TRIES):
                people.reroute(i, person)
                gap = float(np.hypot(*(people.positions()[i, :2] - pose[:2])))
                if gap >= self.scene.robot_radius_m + person.radius_m + CROWD_START_CLEARANCE_M:
                    placed += 1
                    break
                person = replace(person, start_offset_m=float(self.rng.uniform(0.0, 2.0 * length)))
            else:
                people.reroute(i, parked_person())
        rec["people"] = placed
        if not placed:
            rec["skipped"] = f"no graph route of {len(self.members)} near the robot"
        return placed > 0

    def send_away(self, params: FaultParams, t: float) -> None:
        """The crowd walks to nodes beyond its radius (graph distance from the robot), on
        graph edges that keep clear of the robot (a way out through it would hold a
        person up in front of it)."""
        graph, people = self.scene.building.navgraph, self.scene.world.people
        robot = self.scene.pose()[:2]
        dist = self.scene.graph_distance(robot)
        clear = point_segment_distance(robot, graph.edge_segments()) > self.scene.robot_radius_m + LEAVE_ROBOT_GAP_M
        away = NavGraph(graph.nodes, tuple(e for e, ok in zip(graph.edges, clear, strict=True) if ok))
        usable = np.zeros(graph.n_nodes, dtype=bool)
        usable[away.edge_indices().reshape(-1)] = True
        if not usable.any():
            return
        ids, xy = graph.node_ids(), graph.node_xy()
        lo, hi = params.crowd_radius_m + LEAVE_BEYOND_M[0], params.crowd_radius_m + LEAVE_BEYOND_M[1]
        far = ids[usable & (dist >= lo) & (dist <= hi)]
        if not len(far):  # a small building: the farthest node
            ok = usable & np.isfinite(dist)
            far = ids[ok & (dist >= dist[ok].max())] if ok.any() else ids[usable]
        pos = people.positions()
        for i in self.members:
            if people.people[i] == parked_person():
                continue
            d2 = np.where(usable, np.hypot(*(xy - pos[i, :2]).T), np.inf)
            try:
                pts = path_points(away, astar(away, int(ids[np.argmin(d2)]), int(self.rng.choice(far))))
            except InputError:
                continue  # no way out: they walk on where they are
            route = np.vstack([pos[i, :2], pts])
            route = route[np.concatenate([[True], np.hypot(*np.diff(route, axis=0).T) > 1e-9])]
            if len(route) < 2:
                continue
            speed = people.people[i].speed_mps
            people.reroute(i, Person(route=tuple((float(x), float(y)) for x, y in route), speed_mps=speed))
            length = float(np.sum(np.hypot(*np.diff(route, axis=0).T)))
            self.leaving[i] = (t, length / max(speed, 1e-6))

    def park_the_left(self, t: float) -> None:
        """Park a leaving person once at the end of their way out and beyond the camera's
        range (or at the latest after three times the walk)."""
        pos = self.scene.world.people.positions()
        robot = self.scene.pose()[:2]
        for i, (t0, walk_s) in list(self.leaving.items()):
            far = float(np.hypot(*(pos[i, :2] - robot))) > PARK_BEYOND_M
            if (t - t0 >= walk_s - TIME_EPS_S and far) or t - t0 > 3.0 * walk_s + 10.0:
                self.scene.world.people.reroute(i, parked_person())
                del self.leaving[i]
