"""Faults for closed-loop runs: the robot carried off, a camera that fails, wheels that
slip, a bumped camera mount, a crowd, a corridor blocked by something the map lacks.

Faults are scenario settings (a ``[faults]`` table, :class:`FaultsConfig`), scheduled by
distance driven or simulated time (:class:`FaultSchedule`; both in
:mod:`sim.simulator.fault_config`), seeded and logged. :class:`FaultInjector` applies them
around the simulator step: :meth:`FaultInjector.before_step` starts and ends faults that
change the world (teleports, the camera's orientation, people and furniture),
:meth:`FaultInjector.filter_frame` changes what the robot receives (the depth frame and
the odometry increment; the frame's true pose is left as it is). People and furniture a
fault uses must be in the MuJoCo model when it is compiled: :func:`fault_actors` gives
them, parked outside the building.

Fault kinds (the names in the TOML):

- ``kidnap``: the robot is carried to a random free place (uniform over the building's
  largest free region, ``KIDNAP_CLEARANCE_M`` beyond its radius from every wall,
  ``KEEP_OUT_M`` from furniture and people) at a random heading, and stopped. Its wheels
  do not turn: the odometry does not see the move.
- ``blackout``: every pixel 0 (invalid) for ``blackout_s``, as a Kinect whose cable is loose.
- ``dropped``: for ``burst_s`` each frame is lost with probability ``drop_probability``
  (the robot gets ``None``).
- ``corrupt_nan``: for ``burst_s`` a fraction ``nan_fraction`` of the pixels and
  ``nan_rows`` whole rows are NaN (a broken driver).
- ``stale``: for ``burst_s`` the driver repeats the last frame before the burst.
- ``slip``: for ``slip_s`` the odometry reports forward motion at ``slip_speed_mps`` that
  did not happen; at its start the robot is bumped ``bump_m`` in a random direction
  (clear of walls, furniture and people) and turned ``bump_deg``, unseen by the odometry.
- ``tilt``: the camera's pitch and roll on the robot change by ``tilt_deg`` in all (a
  random split, random signs) for the rest of the run: a calibration error the robot
  stack does not know about.
- ``crowd``: ``crowd_size`` people appear around the robot, walking random graph routes
  within ``crowd_radius_m`` of it, for ``crowd_s``; then they walk away and are parked
  once out of the camera's range.
- ``blockage``: a door slab (or a row of boxes, ``blockage_depth_m``) of corridor width
  across the robot's way to the mission's waypoint, 4-8 m ahead of it, where the
  navigation graph has another way to the waypoint (while there is no such place, in an
  open hall, it waits for one, up to ``BLOCKAGE_WAIT_M`` driven); it stays
  ``blockage_s`` (0: the rest of the run). The way is the simulator's own: the graph's
  shortest path from the node nearest the true pose to the waypoint, never the robot's
  plan, so where a blockage lands does not depend on what the robot believes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import mujoco
import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.geometry import (
    compose_pose,
    crosses_any,
    point_segment_distance,
    point_segment_projection,
    segment_distances,
)
from autonomy.maps.graph_builder import graph_components
from autonomy.maps.navgraph import NavGraph
from autonomy.maps.planner import adjacency, astar, dijkstra, path_points
from sim.simulator.actors import Person, furniture_body, parked_person
from sim.simulator.building import Building, random_people
from sim.simulator.fault_config import (
    DURATION_PARAM,
    KIND_PARAMS,
    PANEL_WIDTH_M,
    TIME_EPS_S,
    FaultParams,
    FaultSchedule,
    FaultsConfig,
    fault_actors,
)
from sim.simulator.robot import Odometry
from sim.simulator.step import SimFrame
from sim.simulator.world import World, optical_quat

#: A kidnapped robot lands this far beyond its radius from every wall ...
KIDNAP_CLEARANCE_M = 0.3
#: ... and this far (body to body) from furniture and people.
KEEP_OUT_M = 1.0
#: Random places tried for a kidnap before it is skipped.
KIDNAP_TRIES = 500
#: A bumped robot keeps this much beyond its radius from walls, furniture and people.
BUMP_CLEARANCE_M = 0.05
#: Directions tried for a bump (evenly spaced from a random one).
BUMP_DIRECTIONS = 16
#: A blockage stands this far ahead of the robot along its way to the waypoint (min, max) ...
BLOCKAGE_AHEAD_M = (4.0, 8.0)
#: ... at one of the places this far apart.
BLOCKAGE_STEP_M = 0.25
#: A blockage keeps this much beyond the robot's radius from the robot.
BLOCKAGE_ROBOT_GAP_M = 0.5
#: A blockage due where there is no such place (an open hall, no waypoint) waits for one,
#: looking every this many seconds ...
BLOCKAGE_RETRY_S = 0.5
#: ... while the robot drives up to this far (then it is recorded as skipped).
BLOCKAGE_WAIT_M = 50.0
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


@dataclass
class _Active:
    record: dict
    params: FaultParams
    end_t: float


def _pose_list(p: np.ndarray) -> list[float]:
    return [float(v) for v in p]


def _yaw_quat(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def ray_to_walls(origin: np.ndarray, direction: np.ndarray, walls: np.ndarray) -> float:
    """Distance along a unit ``direction`` from ``origin`` to the first wall (N, 4) it
    meets (inf when none)."""
    a, e = walls[:, :2], walls[:, 2:] - walls[:, :2]
    ao = a - origin
    den = direction[0] * e[:, 1] - direction[1] * e[:, 0]
    ok = np.abs(den) > 1e-12
    den = np.where(ok, den, 1.0)
    t = (ao[:, 0] * e[:, 1] - ao[:, 1] * e[:, 0]) / den
    u = (ao[:, 0] * direction[1] - ao[:, 1] * direction[0]) / den
    hit = ok & (t > 1e-9) & (u >= 0.0) & (u <= 1.0)
    return float(t[hit].min()) if hit.any() else math.inf


class FaultInjector:
    """Applies a run's faults (see the module docstring) around the simulator step.

    Per tick, in this order: :meth:`before_step` (before the pose is read), the simulator
    step, :meth:`filter_frame` on its frame. It reads the world and the mission, never
    the robot stack. Every draw comes from ``rng``; with no fault configured nothing is
    drawn, the world is never touched and frames pass unchanged.
    """

    def __init__(
        self, cfg: FaultsConfig, world: World, building: Building, rng: np.random.Generator, odometry: Odometry, robot_radius_m: float,
        until_m: float = math.inf,
    ) -> None:
        self.cfg = cfg
        self.world = world
        self.building = building
        self.rng = rng
        self.odometry = odometry
        self.robot_radius_m = float(robot_radius_m)
        self.events: list[dict] = []
        """Every fault: kind, t_start, t_end (None while active), distance_m, truth_before,
        truth_after, params, trigger, and what the kind reports (where, skipped ...)."""
        self.schedule = FaultSchedule(cfg, np.random.default_rng(rng.integers(2**63)) if cfg.enabled else rng, until_m)
        self._active: dict[str, _Active] = {}
        self._walls = np.ascontiguousarray(building.vectormap.segments, dtype=np.float64).reshape(-1, 4)
        model = world.model
        self._furniture_bodies = np.array(
            [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, furniture_body(i)) for i in range(len(world.furniture))], dtype=np.int64
        )
        self._furniture_half = np.array([0.5 * math.hypot(f.dims[0], f.dims[1]) for f in world.furniture])
        panels, crowd = fault_actors(cfg)
        self._panels = [world.furniture.index(p) for p in panels if p in world.furniture]
        if len(self._panels) != len(panels):
            raise ValueError("fault injection: the world lacks the blockage's panels; build it with fault_actors(cfg)")
        parked = [i for i, p in enumerate(world.people.people) if p == parked_person()]
        if len(parked) < len(crowd):
            raise ValueError("fault injection: the world lacks the crowd's people; build it with fault_actors(cfg)")
        self._crowd = parked[len(parked) - len(crowd) :]
        self._leaving: dict[int, tuple[float, float]] = {}
        self._robot_from_optical = world.mount.rotation()
        self._t = float(world.data.time)
        self._last_depth: np.ndarray | None = None
        self._stale: np.ndarray | None = None
        self._odom_before: np.ndarray | None = None
        self._adj = None
        self._waiting: tuple[FaultParams, str, float, float] | None = None
        self._next_try = -math.inf
        # The places a kidnap lands on and a bump's fit are read from the building's free
        # space: built now, not at the first such fault, so that a long run's memory is
        # steady from its start.
        if cfg.uses("kidnap"):
            building.prepare_free_spots(self.robot_radius_m + KIDNAP_CLEARANCE_M, self.robot_radius_m)
        elif cfg.uses("slip"):
            building.free_space(self.robot_radius_m)

    # ------------------------------------------------------------------ the loop

    @property
    def active(self) -> list[str]:
        """Kinds active now."""
        return list(self._active)

    def before_step(self, t: float, distance_m: float, goal: int | None) -> list[dict]:
        """Called once per tick before the simulator steps, with the distance driven and
        the mission's current waypoint (a graph node; None: none): starts due faults
        (teleports, tilts, places actors), ends finished ones. Returns the events that
        started this tick."""
        self._t = float(t)
        for kind in [k for k, a in self._active.items() if t >= a.end_t - TIME_EPS_S]:
            self._end(kind, t)
        if self._leaving:
            self._park_the_left(t)
        started = []
        for kind, params, trigger in self.schedule.due(t, distance_m):
            if kind == "blockage":
                self._waiting, self._next_try = (params, trigger, float(t), float(distance_m)), -math.inf
            else:
                started.append(self._start(kind, params, trigger, t, distance_m))
        if self._waiting is not None and t >= self._next_try - TIME_EPS_S:
            started += self._try_blockage(t, distance_m, goal)
        if "slip" in self._active:
            self._odom_before = self.odometry.pose.copy()
        return started

    def filter_frame(self, frame: SimFrame) -> SimFrame:
        """What the robot receives: depth replaced (zeros / NaN / stale copy / None when
        dropped) and odometry increment altered during slip bursts. frame.pose stays the truth."""
        active = self._active
        if not active:
            self._last_depth = frame.depth
            return frame
        depth, inc = frame.depth, frame.increment
        if "stale" in active:
            if self._stale is None:
                self._stale = self._last_depth if self._last_depth is not None else depth
            if self._stale is not None:
                depth = self._stale.copy()
        else:
            self._last_depth = depth
        if "corrupt_nan" in active and depth is not None:
            p = active["corrupt_nan"].params
            depth = depth.copy()
            depth[self.rng.random(depth.shape) < p.nan_fraction] = np.nan
            depth[self.rng.choice(depth.shape[0], size=min(p.nan_rows, depth.shape[0]), replace=False)] = np.nan
        if "blackout" in active and depth is not None:
            depth = np.zeros_like(depth)
        if "dropped" in active and self.rng.random() < active["dropped"].params.drop_probability:
            depth = None
        if "slip" in active and inc is not None:
            dt = frame.t - self._t
            inc = inc + np.array([active["slip"].params.slip_speed_mps * dt, 0.0, 0.0])
            if self._odom_before is not None:
                self.odometry.pose = compose_pose(self._odom_before, inc)
        if depth is frame.depth and inc is frame.increment:
            return frame
        return replace(frame, depth=depth, increment=inc)

    # ------------------------------------------------------------------ start and end

    def _pose(self) -> np.ndarray:
        return self.world.robot.pose(self.world.data)

    def _try_blockage(self, t: float, distance_m: float, goal: int | None) -> list[dict]:
        """Place the waiting blockage if there is a place for it now on the way to the
        waypoint ``goal``; record it as skipped once the robot has driven
        ``BLOCKAGE_WAIT_M`` without one."""
        assert self._waiting is not None
        params, trigger, due_t, due_m = self._waiting
        pose = self._pose()
        spot = self._blockage_spot(pose, self._route(pose, goal))
        if spot is None and distance_m - due_m < BLOCKAGE_WAIT_M:
            self._next_try = t + BLOCKAGE_RETRY_S
            return []
        self._waiting = None
        rec = self._start("blockage", params, trigger, t, distance_m, spot=spot)
        rec.update(due_t=due_t, due_distance_m=due_m)
        return [rec]

    def _start(self, kind: str, params: FaultParams, trigger: str, t: float, distance_m: float, **extra) -> dict:
        if kind in self._active:
            self._active[kind].record["replaced"] = True
            self._end(kind, t)
        before = self._pose()
        rec = {
            "kind": kind,
            "t_start": float(t),
            "t_end": None,
            "distance_m": float(distance_m),
            "trigger": trigger,
            "truth_before": _pose_list(before),
            "truth_after": None,
            "params": {k: getattr(params, k) for k in KIND_PARAMS[kind]},
        }
        ok = getattr(self, f"_start_{kind}")(rec, params, before, **extra)
        rec["truth_after"] = _pose_list(self._pose())
        self.events.append(rec)
        duration = DURATION_PARAM.get(kind)
        if not ok or kind == "kidnap":
            rec["t_end"] = rec["t_start"]
        else:
            d = getattr(params, duration) if duration else 0.0
            self._active[kind] = _Active(rec, params, t + d if d > 0 else math.inf)
        return rec

    def _end(self, kind: str, t: float) -> None:
        a = self._active.pop(kind)
        a.record["t_end"] = float(t)
        if kind == "stale":
            self._stale = None
        elif kind == "slip":
            self._odom_before = None
        elif kind == "crowd":
            self._send_away(a.params, t)
        elif kind == "blockage":
            self._park_panels()

    def _teleport(self, pose: np.ndarray) -> None:
        """Move the robot (stopped) without the odometry seeing it."""
        w = self.world
        w.robot.set_pose(w.data, (float(pose[0]), float(pose[1]), float(pose[2])))
        mujoco.mj_forward(w.model, w.data)
        self.odometry.rebase(w.robot.pose(w.data))

    # ------------------------------------------------------------------ kinds

    def _start_kidnap(self, rec: dict, params: FaultParams, pose: np.ndarray) -> bool:
        clearance = self.robot_radius_m + KIDNAP_CLEARANCE_M
        for _ in range(KIDNAP_TRIES):
            xy = self.building.free_spot(self.rng, clearance, self.robot_radius_m)
            if xy is None:
                break
            if self._clear_of_actors(xy, KEEP_OUT_M):
                self._teleport(np.array([xy[0], xy[1], self.rng.uniform(-math.pi, math.pi)]))
                return True
        rec["skipped"] = f"no place {clearance:.2f} m from the walls and {KEEP_OUT_M} m from furniture and people"
        return False

    def _start_blackout(self, rec: dict, params: FaultParams, pose: np.ndarray) -> bool:
        return True

    _start_dropped = _start_corrupt_nan = _start_stale = _start_blackout

    def _start_slip(self, rec: dict, params: FaultParams, pose: np.ndarray) -> bool:
        rec["bump"] = None
        if params.bump_m <= 0 and params.bump_deg <= 0:
            return True
        dth = math.radians(params.bump_deg) * (1.0 if self.rng.random() < 0.5 else -1.0)
        a0 = self.rng.uniform(0.0, 2.0 * math.pi)
        for k in range(BUMP_DIRECTIONS):
            a = a0 + 2.0 * math.pi * k / BUMP_DIRECTIONS
            xy = pose[:2] + params.bump_m * np.array([math.cos(a), math.sin(a)])
            if self._fits(pose[:2], xy):
                self._teleport(np.array([xy[0], xy[1], pose[2] + dth]))
                rec["bump"] = {"dx": float(xy[0] - pose[0]), "dy": float(xy[1] - pose[1]), "dtheta_deg": math.degrees(dth)}
                return True
        rec["bump_skipped"] = "no direction clear of walls, furniture and people"
        return True

    def _start_tilt(self, rec: dict, params: FaultParams, pose: np.ndarray) -> bool:
        phi = self.rng.uniform(0.0, 2.0 * math.pi)
        pitch, roll = math.radians(params.tilt_deg) * math.cos(phi), math.radians(params.tilt_deg) * math.sin(phi)
        # Pitch about the robot's y axis (positive: further down, as CameraMount's pitch),
        # roll about its x axis (positive: the camera's left side up).
        self._robot_from_optical = _rot_y(pitch) @ _rot_x(roll) @ self._robot_from_optical
        w = self.world
        w.model.cam_quat[w.camera_id] = optical_quat(self._robot_from_optical)
        mujoco.mj_forward(w.model, w.data)
        rec.update(pitch_down_deg=math.degrees(pitch), roll_deg=math.degrees(roll))
        rec["robot_from_optical"] = [[float(v) for v in row] for row in self._robot_from_optical]
        return True

    def _start_crowd(self, rec: dict, params: FaultParams, pose: np.ndarray) -> bool:
        graph = self.building.navgraph
        dist = self._graph_distance(pose[:2])
        ids = graph.node_ids()
        routes: tuple[Person, ...] = ()
        # Routes between nodes within half the radius keep every point of them within it.
        for r in (0.5 * params.crowd_radius_m, params.crowd_radius_m):
            nodes = ids[dist <= r]
            if len(nodes) >= 2:
                routes = random_people(graph, params.crowd_size, self.rng, nodes)
            if routes:
                break
        people = self.world.people
        placed = 0
        for i, person in zip(self._crowd, routes, strict=False):
            self._leaving.pop(i, None)
            length = float(np.sum(np.hypot(*np.diff(np.asarray(person.route), axis=0).T)))
            for _ in range(CROWD_START_TRIES):
                people.reroute(i, person)
                gap = float(np.hypot(*(people.positions()[i, :2] - pose[:2])))
                if gap >= self.robot_radius_m + person.radius_m + CROWD_START_CLEARANCE_M:
                    placed += 1
                    break
                person = replace(person, start_offset_m=float(self.rng.uniform(0.0, 2.0 * length)))
            else:
                people.reroute(i, parked_person())
        rec["people"] = placed
        if not placed:
            rec["skipped"] = f"no graph route of {len(self._crowd)} near the robot"
        return placed > 0

    def _start_blockage(self, rec: dict, params: FaultParams, pose: np.ndarray, spot: tuple | None = None) -> bool:
        if spot is None:
            rec["skipped"] = (
                f"no corridor up to {self.cfg.blockage_max_width_m} m wide {BLOCKAGE_AHEAD_M[0]}-{BLOCKAGE_AHEAD_M[1]} m "
                f"ahead on the way to the waypoint with another route to it within {BLOCKAGE_WAIT_M} m driven"
            )
            return False
        a, b, d, ahead, cut = spot
        width = float(np.hypot(*(b - a)))
        n = math.ceil(width / PANEL_WIDTH_M - 1e-9)
        u = (b - a) / width
        yaw = math.atan2(d[1], d[0])
        model = self.world.model
        for k, i in enumerate(self._panels):
            bid = self._furniture_bodies[i]
            if k < n:
                c = a + u * (0.5 * PANEL_WIDTH_M + (width - PANEL_WIDTH_M) * (k / (n - 1) if n > 1 else 0.5))
                model.body_pos[bid] = [c[0], c[1], 0.0]
                model.body_quat[bid] = _yaw_quat(yaw)
        mujoco.mj_forward(model, self.world.data)
        graph = self.building.navgraph
        rec["where"] = {
            "centre": [float(v) for v in 0.5 * (a + b)],
            "ends": [[float(v) for v in a], [float(v) for v in b]],
            "width_m": width,
            "ahead_m": ahead,
            "panels": n,
            "cut_edges": [[int(graph.edges[j].s0_id), int(graph.edges[j].s1_id)] for j in cut],
        }
        return True

    # ------------------------------------------------------------------ helpers

    def _actors(self) -> tuple[np.ndarray, np.ndarray]:
        """Centres (n, 2) and footprint radii (n,) of the furniture and the people where they are now."""
        model = self.world.model
        f_xy = model.body_pos[self._furniture_bodies, :2] if len(self._furniture_bodies) else np.zeros((0, 2))
        people = self.world.people
        p_xy = people.positions()[:, :2] if len(people.people) else np.zeros((0, 2))
        p_r = np.array([p.radius_m for p in people.people])
        return np.vstack([f_xy, p_xy]), np.concatenate([self._furniture_half, p_r])

    def _clear_of_actors(self, xy: np.ndarray, gap_m: float) -> bool:
        centres, radii = self._actors()
        if not len(centres):
            return True
        return bool(np.all(np.hypot(*(centres - xy).T) >= self.robot_radius_m + radii + gap_m))

    def _fits(self, start: np.ndarray, xy: np.ndarray) -> bool:
        """Whether the robot fits at ``xy`` (the building's free space with a margin, clear
        of furniture and people) and gets there from ``start`` through no wall."""
        fs = self.building.free_space(self.robot_radius_m)
        i, j = fs.cell_of(xy)
        if fs.region[i, j] < 0 or fs.dist[i, j] - fs.error_m < self.robot_radius_m + BUMP_CLEARANCE_M:
            return False
        if len(self._walls) and crosses_any(start, xy, self._walls):
            return False
        return self._clear_of_actors(xy, BUMP_CLEARANCE_M)

    def _graph_distance(self, xy: np.ndarray) -> np.ndarray:
        """Graph distance of every node (node order) from the node nearest ``xy``."""
        graph = self.building.navgraph
        if self._adj is None:
            self._adj = adjacency(graph)
        k = graph.index_of(graph.nearest_node(float(xy[0]), float(xy[1])))
        return dijkstra(self._adj, {k: float(np.hypot(*(graph.node_xy()[k] - xy)))})[0]

    def _send_away(self, params: FaultParams, t: float) -> None:
        """The crowd walks to nodes beyond its radius (graph distance from the robot), on
        graph edges that keep clear of the robot (a way out through it would hold a
        person up in front of it)."""
        graph, people = self.building.navgraph, self.world.people
        robot = self._pose()[:2]
        dist = self._graph_distance(robot)
        clear = point_segment_distance(robot, graph.edge_segments()) > self.robot_radius_m + LEAVE_ROBOT_GAP_M
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
        for i in self._crowd:
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
            self._leaving[i] = (t, length / max(speed, 1e-6))

    def _park_the_left(self, t: float) -> None:
        """Park a leaving person once at the end of their way out and beyond the camera's
        range (or at the latest after three times the walk)."""
        pos = self.world.people.positions()
        robot = self._pose()[:2]
        for i, (t0, walk_s) in list(self._leaving.items()):
            far = float(np.hypot(*(pos[i, :2] - robot))) > PARK_BEYOND_M
            if (t - t0 >= walk_s - TIME_EPS_S and far) or t - t0 > 3.0 * walk_s + 10.0:
                self.world.people.reroute(i, parked_person())
                del self._leaving[i]

    def _park_panels(self) -> None:
        model = self.world.model
        for i in self._panels:
            f, bid = self.world.furniture[i], self._furniture_bodies[i]
            model.body_pos[bid] = [f.x, f.y, 0.0]
            model.body_quat[bid] = _yaw_quat(f.yaw)
        mujoco.mj_forward(model, self.world.data)

    def _route(self, pose: np.ndarray, goal: int | None) -> np.ndarray | None:
        """The way (K, 2) from the true pose to the waypoint ``goal``: the pose, then the
        navigation graph's shortest path from the node nearest it (:func:`astar`); None
        without a waypoint or a path."""
        if goal is None:
            return None
        graph = self.building.navgraph
        try:
            nodes = astar(graph, graph.nearest_node(float(pose[0]), float(pose[1])), int(goal))
        except InputError:
            return None
        return np.vstack([np.asarray(pose[:2], dtype=np.float64), path_points(graph, nodes)])

    def _blockage_spot(
        self, pose: np.ndarray, way_xy: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray] | None:
        """Ends (a, b) of a wall-to-wall line across the way ``way_xy`` 4-8 m ahead, the
        way's direction there, the distance ahead and the graph edges it cuts; None when no
        place there is a corridor (up to ``blockage_max_width_m``) whose blocking leaves the
        graph a way from the robot to the way's end."""
        if way_xy is None or len(way_xy) < 2 or not len(self._panels):
            return None
        way = np.asarray(way_xy, dtype=np.float64).reshape(-1, 2)
        segs = np.concatenate([way[:-1], way[1:]], axis=1)
        lengths = np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
        cum = np.concatenate([[0.0], np.cumsum(lengths)])
        frac, dist = point_segment_projection(pose[:2], segs)
        k0 = int(np.argmin(dist))
        s0 = cum[k0] + frac[k0] * lengths[k0]
        ahead = np.arange(BLOCKAGE_AHEAD_M[0], BLOCKAGE_AHEAD_M[1] + 1e-9, BLOCKAGE_STEP_M)
        ahead = ahead[s0 + ahead < cum[-1]]
        if not len(ahead):
            return None
        graph = self.building.navgraph
        edges, edge_ij = graph.edge_segments(), graph.edge_indices()
        src = graph.index_of(graph.nearest_node(float(pose[0]), float(pose[1])))
        dst = graph.index_of(graph.nearest_node(float(way[-1, 0]), float(way[-1, 1])))
        for s_ahead in np.roll(ahead, -int(self.rng.integers(len(ahead)))):
            s = s0 + s_ahead
            k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(segs) - 1))
            if lengths[k] <= 1e-9:
                continue
            d = (segs[k, 2:] - segs[k, :2]) / lengths[k]
            p = segs[k, :2] + (s - cum[k]) * d
            n = np.array([-d[1], d[0]])
            left, right = ray_to_walls(p, n, self._walls), ray_to_walls(p, -n, self._walls)
            width = left + right
            if not (2.0 * self.robot_radius_m <= width <= self.cfg.blockage_max_width_m):
                continue
            a, b = p - right * n, p + left * n
            line = np.concatenate([a, b])
            if point_segment_distance(pose[:2], line[None])[0] < self.robot_radius_m + BLOCKAGE_ROBOT_GAP_M:
                continue
            cut = np.flatnonzero(segment_distances(edges, np.tile(line, (len(edges), 1))) < self.robot_radius_m)
            if not len(cut):
                continue
            comp = graph_components(graph.n_nodes, np.delete(edge_ij, cut, axis=0))
            if src != dst and comp[src] == comp[dst]:
                return a, b, d, float(s_ahead), cut
        return None
