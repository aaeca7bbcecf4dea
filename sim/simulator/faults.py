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
them, parked outside the building. The pieces it is made of: :mod:`~sim.simulator.fault_scene`
(the world as the faults read and move it), :mod:`~sim.simulator.fault_frames` (the frame
filters), :mod:`~sim.simulator.fault_crowd` and :mod:`~sim.simulator.fault_blockage` (those
two kinds' actors and bookkeeping), :mod:`~sim.simulator.fault_record` (the event record).

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
  open hall, it waits for one, up to ``fault_blockage.BLOCKAGE_WAIT_M`` driven); it stays
  ``blockage_s`` (0: the rest of the run). The way is the simulator's own: the graph's
  shortest path from the node nearest the true pose to the waypoint, never the robot's
  plan, so where a blockage lands does not depend on what the robot believes.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from sim.simulator.actors import parked_person
from sim.simulator.building import Building
from sim.simulator.fault_blockage import FaultBlockage, Spot
from sim.simulator.fault_config import (
    DURATION_PARAM,
    TIME_EPS_S,
    FaultParams,
    FaultSchedule,
    FaultsConfig,
    fault_actors,
)
from sim.simulator.fault_crowd import FaultCrowd
from sim.simulator.fault_frames import FrameFaults
from sim.simulator.fault_record import ActiveFault, new_record, pose_list
from sim.simulator.fault_scene import FaultScene
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


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


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
        self.rng = rng
        self.events: list[dict] = []
        """Every fault: kind, t_start, t_end (None while active), distance_m, truth_before,
        truth_after, params, trigger, and what the kind reports (where, skipped ...)."""
        self.schedule = FaultSchedule(cfg, np.random.default_rng(rng.integers(2**63)) if cfg.enabled else rng, until_m)
        self._active: dict[str, ActiveFault] = {}
        self.scene = FaultScene(world, building, odometry, robot_radius_m)
        """The world, building and odometry the faults act on."""
        panels, crowd = fault_actors(cfg)
        panel_ids = [world.furniture.index(p) for p in panels if p in world.furniture]
        if len(panel_ids) != len(panels):
            raise ValueError("fault injection: the world lacks the blockage's panels; build it with fault_actors(cfg)")
        parked = [i for i, p in enumerate(world.people.people) if p == parked_person()]
        if len(parked) < len(crowd):
            raise ValueError("fault injection: the world lacks the crowd's people; build it with fault_actors(cfg)")
        self.blockage = FaultBlockage(self.scene, rng, panel_ids, cfg.blockage_max_width_m)
        """The blockage's panels and placement."""
        self.crowd = FaultCrowd(self.scene, rng, parked[len(parked) - len(crowd) :])
        """The crowd's people."""
        self.frames = FrameFaults(rng, odometry, float(world.data.time))
        """The filters of what the robot receives."""
        self._robot_from_optical = world.mount.rotation()
        # The places a kidnap lands on and a bump's fit are read from the building's free
        # space: built now, not at the first such fault, so that a long run's memory is
        # steady from its start.
        radius = self.scene.robot_radius_m
        if cfg.uses("kidnap"):
            building.prepare_free_spots(radius + KIDNAP_CLEARANCE_M, radius)
        elif cfg.uses("slip"):
            building.free_space(radius)

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
        self.frames.before_step(t)
        for kind in [k for k, a in self._active.items() if t >= a.end_t - TIME_EPS_S]:
            self._end(kind, t)
        if self.crowd.leaving:
            self.crowd.park_the_left(t)
        started = []
        for kind, params, trigger in self.schedule.due(t, distance_m):
            if kind == "blockage":
                self.blockage.wait(params, trigger, t, distance_m)
            else:
                started.append(self._start(kind, params, trigger, t, distance_m))
        if self.blockage.looks_now(t):
            started += self._try_blockage(t, distance_m, goal)
        if "slip" in self._active:
            self.frames.hold_odometry()
        return started

    def filter_frame(self, frame: SimFrame) -> SimFrame:
        """What the robot receives: depth replaced (zeros / NaN / stale copy / None when
        dropped) and odometry increment altered during slip bursts. frame.pose stays the truth."""
        return self.frames.filter(frame, self._active)

    # ------------------------------------------------------------------ start and end

    def _try_blockage(self, t: float, distance_m: float, goal: int | None) -> list[dict]:
        """Place the waiting blockage if there is a place for it now on the way to the
        waypoint ``goal``; record it as skipped once the robot has driven far without one."""
        found = self.blockage.look(t, distance_m, goal)
        if found is None:
            return []
        pending, spot = found
        rec = self._start("blockage", pending.params, pending.trigger, t, distance_m, spot=spot)
        rec.update(due_t=pending.due_t, due_distance_m=pending.due_m)
        return [rec]

    def _start(self, kind: str, params: FaultParams, trigger: str, t: float, distance_m: float, **extra) -> dict:
        if kind in self._active:
            self._active[kind].record["replaced"] = True
            self._end(kind, t)
        before = self.scene.pose()
        rec = new_record(kind, params, trigger, t, distance_m, before)
        ok = getattr(self, f"_start_{kind}")(rec, params, before, **extra)
        rec["truth_after"] = pose_list(self.scene.pose())
        self.events.append(rec)
        duration = DURATION_PARAM.get(kind)
        if not ok or kind == "kidnap":
            rec["t_end"] = rec["t_start"]
        else:
            d = getattr(params, duration) if duration else 0.0
            self._active[kind] = ActiveFault(rec, params, t + d if d > 0 else math.inf)
        return rec

    def _end(self, kind: str, t: float) -> None:
        a = self._active.pop(kind)
        a.record["t_end"] = float(t)
        self.frames.end(kind)
        if kind == "crowd":
            self.crowd.send_away(a.params, t)
        elif kind == "blockage":
            self.blockage.park()

    # ------------------------------------------------------------------ kinds

    def _start_kidnap(self, rec: dict, params: FaultParams, pose: np.ndarray) -> bool:
        radius = self.scene.robot_radius_m
        clearance = radius + KIDNAP_CLEARANCE_M
        for _ in range(KIDNAP_TRIES):
            xy = self.scene.building.free_spot(self.rng, clearance, radius)
            if xy is None:
                break
            if self.scene.clear_of_actors(xy, KEEP_OUT_M):
                self.scene.teleport(np.array([xy[0], xy[1], self.rng.uniform(-math.pi, math.pi)]))
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
            if self.scene.fits(pose[:2], xy, BUMP_CLEARANCE_M):
                self.scene.teleport(np.array([xy[0], xy[1], pose[2] + dth]))
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
        w = self.scene.world
        w.model.cam_quat[w.camera_id] = optical_quat(self._robot_from_optical)
        mujoco.mj_forward(w.model, w.data)
        rec.update(pitch_down_deg=math.degrees(pitch), roll_deg=math.degrees(roll))
        rec["robot_from_optical"] = [[float(v) for v in row] for row in self._robot_from_optical]
        return True

    def _start_crowd(self, rec: dict, params: FaultParams, pose: np.ndarray) -> bool:
        return self.crowd.start(rec, params, pose)

    def _start_blockage(self, rec: dict, params: FaultParams, pose: np.ndarray, spot: Spot | None = None) -> bool:
        return self.blockage.place(rec, spot)
