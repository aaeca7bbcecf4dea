"""Unmapped objects: furniture (static primitive geoms) and people (kinematic walkers).

Neither is in the vector map, so to the localization they are clutter, and to the
obstacle avoidance they are obstacles: exactly the paper's setting (BV2012, VI).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from autonomy.common.constants import ROBOT_RADIUS_M
from autonomy.common.errors import InputError
from autonomy.common.geometry import rectangle_corners
from sim.simulator.people_walls import WallClearance
from sim.simulator.person_route import RoutePath
from sim.simulator.robot import COLL_PEOPLE, COLL_ROBOT, COLL_STATIC

FURNITURE_PREFIX = "furniture_"
"""MJCF body names of the furniture: this prefix and the piece's index ..."""
PERSON_PREFIX = "person_"
"""... and of the people (their mocap bodies): this prefix and the person's index."""


def furniture_body(i: int) -> str:
    """The MJCF body name of furniture piece ``i``."""
    return f"{FURNITURE_PREFIX}{i}"


def person_body(i: int) -> str:
    """The MJCF body name of person ``i``."""
    return f"{PERSON_PREFIX}{i}"


def person_index(body: str) -> int | None:
    """The index of the person whose body is named ``body`` (None: not a person's)."""
    rest = body[len(PERSON_PREFIX) :] if body.startswith(PERSON_PREFIX) else ""
    return int(rest) if rest.isdigit() else None

FURNITURE_KINDS = ("table", "chair", "box", "cabinet")

#: Where unused furniture and people are parked (outside any building).
PARK_XY = (-1.0e4, -1.0e4)

_FURNITURE_DEFAULT_SIZE = {
    # (length x, width y, height z) in metres
    "table": (1.2, 0.7, 0.74),
    "chair": (0.45, 0.45, 0.9),
    "box": (0.5, 0.5, 0.5),
    "cabinet": (0.9, 0.45, 1.8),
}


@dataclass(frozen=True)
class Furniture:
    """One piece of furniture standing on the floor."""

    kind: str = "box"
    """One of table, chair, box, cabinet."""
    x: float = 0.0
    """Centre x in the world frame (m)."""
    y: float = 0.0
    """Centre y in the world frame (m)."""
    yaw: float = 0.0
    """Heading (rad)."""
    size: tuple[float, ...] = ()
    """(length, width, height) in metres; empty = the kind's default."""

    def __post_init__(self) -> None:
        if self.kind not in FURNITURE_KINDS:
            raise InputError(f"furniture kind {self.kind!r}: expected one of {', '.join(FURNITURE_KINDS)}")
        if self.size and (len(self.size) != 3 or min(self.size) <= 0):
            raise InputError(f"furniture size {self.size!r}: expected three positive numbers (l, w, h)")

    @property
    def dims(self) -> tuple[float, float, float]:
        s = self.size or _FURNITURE_DEFAULT_SIZE[self.kind]
        return float(s[0]), float(s[1]), float(s[2])

    @property
    def half_diagonal(self) -> float:
        """Half the footprint's diagonal: the farthest any of it lies from its centre."""
        return 0.5 * math.hypot(self.dims[0], self.dims[1])

    def outline(self) -> np.ndarray:
        """(4, 4) segments (x0, y0, x1, y1) round the piece's footprint (length along its yaw)."""
        length, width, _ = self.dims
        corners = rectangle_corners(self.x, self.y, self.yaw, length, width)
        return np.hstack([corners, np.roll(corners, -1, axis=0)])


@dataclass(frozen=True)
class Person:
    """A person walking a polyline route at constant speed (kinematic, mocap-driven)."""

    route: tuple[tuple[float, float], ...] = ()
    """Waypoints (x, y) in metres; at least two."""
    speed_mps: float = 1.2
    """Walking speed."""
    loop: bool = False
    """True: closed loop back to the first point; False: walk back and forth."""
    start_offset_m: float = 0.0
    """Distance along the route at t = 0."""
    radius_m: float = 0.22
    """Body radius."""
    height_m: float = 1.75
    """Body height."""

    def __post_init__(self) -> None:
        if len(self.route) < 2:
            raise InputError("person route: expected at least two (x, y) points")
        for p in self.route:
            if len(p) != 2 or not all(math.isfinite(float(c)) for c in p):
                raise InputError(f"person route point {p!r}: expected two finite numbers")
        if not self.speed_mps >= 0:
            raise InputError(f"person speed_mps {self.speed_mps!r}: expected a number >= 0")


def parked_person() -> Person:
    """A person standing still at ``PARK_XY``: a body compiled into the world for later use."""
    return Person(route=(PARK_XY, (PARK_XY[0] + 1.0, PARK_XY[1])), speed_mps=0.0)


def _yaw_quat(yaw: float) -> list[float]:
    return [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]


_WOOD_RGBA = [0.55, 0.4, 0.25, 1.0]
_BOX = mujoco.mjtGeom.mjGEOM_BOX


def add_furniture(spec: mujoco.MjSpec, items: tuple[Furniture, ...]) -> None:
    """Add each piece as a static body of primitive geoms named ``furniture_<i>``."""
    kw = dict(contype=COLL_STATIC, conaffinity=COLL_ROBOT, group=1)
    for i, f in enumerate(items):
        lx, ly, h = f.dims
        b = spec.worldbody.add_body(name=furniture_body(i), pos=[f.x, f.y, 0.0], quat=_yaw_quat(f.yaw))
        if f.kind == "table":
            _add_table(b, lx, ly, h, kw)
        elif f.kind == "chair":
            _add_chair(b, lx, ly, h, kw)
        else:
            color = [0.6, 0.5, 0.35, 1.0] if f.kind == "box" else [0.5, 0.5, 0.55, 1.0]
            b.add_geom(type=_BOX, size=[lx / 2, ly / 2, h / 2], pos=[0, 0, h / 2], rgba=color, **kw)


def _add_legs(b, leg: float, x: float, y: float, half_h: float, kw: dict) -> None:
    """Four square legs ``2 leg`` wide, centred at (+-x, +-y), ``2 half_h`` tall from the floor."""
    for sx in (-1, 1):
        for sy in (-1, 1):
            b.add_geom(type=_BOX, size=[leg, leg, half_h], pos=[sx * x, sy * y, half_h], rgba=_WOOD_RGBA, **kw)


def _add_table(b, lx: float, ly: float, h: float, kw: dict) -> None:
    """A 3 cm top at height ``h`` on four legs set in from its corners."""
    top = 0.03
    b.add_geom(type=_BOX, size=[lx / 2, ly / 2, top / 2], pos=[0, 0, h - top / 2], rgba=_WOOD_RGBA, **kw)
    leg = 0.025
    _add_legs(b, leg, lx / 2 - 2 * leg, ly / 2 - 2 * leg, (h - top) / 2, kw)


def _add_chair(b, lx: float, ly: float, h: float, kw: dict) -> None:
    """A seat at 0.45 m, a back up to ``h`` along its -x edge, and four legs at its corners."""
    seat_h = 0.45
    b.add_geom(type=_BOX, size=[lx / 2, ly / 2, 0.025], pos=[0, 0, seat_h], rgba=_WOOD_RGBA, **kw)
    b.add_geom(
        type=_BOX, size=[0.02, ly / 2, (h - seat_h) / 2], pos=[-lx / 2 + 0.02, 0, (h + seat_h) / 2], rgba=_WOOD_RGBA, **kw
    )
    leg = 0.02
    _add_legs(b, leg, lx / 2 - leg, ly / 2 - leg, seat_h / 2, kw)


def add_people(spec: mujoco.MjSpec, people: tuple[Person, ...]) -> None:
    """Add each person as a mocap body ``person_<i>``: a capsule torso and a sphere head."""
    kw = dict(contype=COLL_PEOPLE, conaffinity=COLL_ROBOT, group=1)
    for i, p in enumerate(people):
        b = spec.worldbody.add_body(name=person_body(i), mocap=True, pos=[p.route[0][0], p.route[0][1], 0.0])
        head_r = 0.11
        body_top = p.height_m - 2 * head_r
        half_len = max(0.05, (body_top - 2 * p.radius_m) / 2)
        b.add_geom(
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            size=[p.radius_m, half_len, 0.0],
            pos=[0, 0, p.radius_m + half_len],
            rgba=[0.8, 0.45, 0.35, 1.0],
            **kw,
        )
        b.add_geom(
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[head_r, 0, 0],
            pos=[0, 0, p.height_m - head_r],
            rgba=[0.9, 0.75, 0.6, 1.0],
            **kw,
        )


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Distance from point p to segment a-b (2D): the scalar form of
    :func:`autonomy.common.geometry.point_segment_distance` for the people's per-step checks (a few per person
    and frame, where building (N, 4) arrays cost more than the arithmetic)."""
    d = b - a
    L2 = float(d @ d)
    t = 0.0 if L2 <= 0 else min(max(float((p - a) @ d) / L2, 0.0), 1.0)
    return float(np.hypot(*(p - a - t * d)))


class PeopleController:
    """Moves the people's mocap bodies along their routes as simulated time passes.

    People are polite pedestrians: when the robot is ahead of a person within
    ``notice_m``, the person steps up to ``step_aside_m`` to the right of the route
    (to the left if the robot is to their right; never closer than 5 cm to a wall), and
    waits while the robot is within ``pause_m`` in front — for at most ``max_wait_s``,
    then they walk on past it, stepped aside, back to the route only once the robot is
    ``clear_behind_m`` behind them.
    Otherwise they walk their route at constant speed, back and forth or looped. Where a
    back-and-forth route ends, they turn round where they stand (a person stepped aside
    stays on the same side of the corridor, now on their other hand).
    Nobody walks into the robot: a person whose next step would bring them closer than
    ``personal_space_m`` (plus both radii) to where the robot is or, going on as it
    goes, will be within ``anticipate_s``, stays put for that step (a side step that
    keeps clear is still taken) — people see a robot coming round a corner even when
    its camera cannot see them, and do not step into its way (a person stepped aside
    going round their route's corner would swing across a robot driving past there,
    into its blind zone). From a robot on the move (faster than
    ``moving_mps``) they keep ``pass_gap_m`` rather than ``personal_space_m``: walking
    past it 5 cm abeam, out of its camera's view, they would be in the way of its next turn.
    Nor do people stand still while a robot drives at them: when the robot closes
    in to within ``retreat_gap_m`` of a person's body and, going on as it goes, would be
    inside their personal space within ``retreat_horizon_s``, the person steps back, away from
    it (out of its way, sideways to its motion, when it drives faster than
    ``retreat_sideways_mps``), at ``retreat_speed_mps`` (slower than the robot's cruise, and
    never into a wall: 5 cm from it, or ``squeeze_m`` where 5 cm leaves no way out).
    Without that, a person whose route runs through the robot would wait right beside it,
    out of the camera's view, until the robot drives off sideways into them. A person on a
    back-and-forth route held up by the robot (the personal-space rule) for longer than
    ``max_blocked_s`` turns back, as people do when a robot stands in a doorway they
    wanted to pass; people on a looped route wait. Following a robot that backs slowly
    along their route counts as held up until they are ``clear_of_robot_m`` beyond the
    personal space (else such a person would tail the robot just beyond it, in the
    camera's blind zone, until it drives forward into them). A robot that drives into a person still
    collides, and that is counted.

    Where a person is on their route at an arc length is :class:`RoutePath`'s; which
    places keep off the walls, and which step back does, is :class:`WallClearance`'s.
    """

    notice_m = 2.5
    clear_behind_m = 1.0
    step_aside_m = 0.95
    pause_m = 1.0
    max_wait_s = 2.0
    side_speed_mps = 0.8
    personal_space_m = 0.15
    retreat_gap_m = 0.3
    retreat_speed_mps = 0.5
    retreat_horizon_s = 1.0
    squeeze_m = 0.01
    anticipate_s = 2.0
    pass_gap_m = 0.35
    moving_mps = 0.1
    retreat_sideways_mps = 0.1
    max_blocked_s = 3.0
    clear_of_robot_m = 0.3

    def __init__(
        self, people: tuple[Person, ...], mocap_ids: np.ndarray, walls: np.ndarray | None = None, robot_radius_m: float = ROBOT_RADIUS_M
    ) -> None:
        self.people = people
        self.robot_radius_m = float(robot_radius_m)
        self.mocap_ids = mocap_ids
        self._walls = WallClearance(walls)
        self._routes = [RoutePath.of(p.route, p.loop) for p in people]
        self.reset()

    @property
    def walls(self) -> np.ndarray:
        """The walls (N, 4) people keep off."""
        return self._walls.walls

    def reroute(self, i: int, person: Person) -> None:
        """Person ``i`` walks ``person``'s route from its ``start_offset_m`` on (a parked
        person called in, or sent away); everyone else walks on as they were."""
        self.people = (*self.people[:i], person, *self.people[i + 1 :])
        self._routes[i] = RoutePath.of(person.route, person.loop)
        self._s[i] = person.start_offset_m
        self._side[i] = self._waited[i] = self._blocked[i] = 0.0
        self._state[i] = self._place(i)

    def reset(self, robot_xy: np.ndarray | None = None) -> None:
        """People back at their start offsets. With the robot's position, a person whose
        start would overlap the robot (or stand within ``clear_of_robot_m`` of it) starts
        further along their route: MuJoCo resolves a body placed inside the robot by
        shoving the robot away at metres per second (a run began with the robot thrown
        4 m into a wall)."""
        self._s = np.array([p.start_offset_m for p in self.people], dtype=np.float64)
        self._side = np.zeros(len(self.people))
        self._waited = np.zeros(len(self.people))
        self._blocked = np.zeros(len(self.people))
        self._t = 0.0
        self._robot_prev: np.ndarray | None = None
        self._state = np.zeros((len(self.people), 3))
        for i in range(len(self.people)):
            self._state[i] = self._place(i)
            if robot_xy is not None:
                self._start_clear_of(i, np.asarray(robot_xy, dtype=np.float64)[:2])

    def _start_clear_of(self, i: int, robot_xy: np.ndarray, step_m: float = 0.25) -> None:
        """Person ``i`` moved on along their route until clear of the robot at ``robot_xy``
        (left where they were when no point of the route is)."""
        gap = self.robot_radius_m + self.people[i].radius_m + self.clear_of_robot_m
        s0 = self._s[i]
        span = self._routes[i].length * (1.0 if self.people[i].loop else 2.0)
        k = 0
        while float(np.hypot(*(self._state[i][:2] - robot_xy))) < gap:
            k += 1
            if k * step_m > span:
                self._s[i] = s0
                self._state[i] = self._place(i)
                return
            self._s[i] = s0 + k * step_m
            self._state[i] = self._place(i)

    @classmethod
    def from_model(
        cls, model: mujoco.MjModel, people: tuple[Person, ...], walls: np.ndarray | None = None, robot_radius_m: float = ROBOT_RADIUS_M
    ) -> PeopleController:
        ids = []
        for i in range(len(people)):
            bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, person_body(i))
            ids.append(model.body_mocapid[bid])
        return cls(people, np.array(ids, dtype=int), walls, robot_radius_m)

    def _route_point(self, i: int, s: float) -> tuple[np.ndarray, np.ndarray]:
        """Position and unit walking direction of person ``i``'s route at arc length s."""
        return self._routes[i].point(s)

    def _turn_back(self, i: int) -> None:
        """Turn a person on a back-and-forth route round where they stand."""
        s = self._routes[i].turned_back(self._s[i])
        if s is None:
            return
        self._s[i] = s
        self._side[i] = -self._side[i]

    def _place(self, i: int) -> np.ndarray:
        pos, d = self._route_point(i, self._s[i])
        right = np.array([d[1], -d[0]])
        return np.array([*(pos + self._side[i] * right), math.atan2(d[1], d[0])])

    def _side_is_clear(self, i: int, pos: np.ndarray) -> bool:
        """Whether person ``i``'s body at ``pos`` keeps 5 cm from every wall."""
        return self._walls.is_clear(pos, self.people[i].radius_m)

    def _keep_off_walls(self, i: int) -> None:
        """Walking on stepped aside, a person keeps 5 cm off the walls: where the corridor
        narrows (a door frame after the doorway they stepped aside in), their offset
        shrinks as far as it must. Walking on at the offset they had, people would walk
        through the corridor's wall (people are not stopped by walls, only the robot is),
        or wait half inside a door frame's end, where no step back is clear of it."""
        side = self._side[i]
        if not len(self.walls) or abs(side) < 1e-9:
            return
        pos, d = self._route_point(i, self._s[i])
        right = np.array([d[1], -d[0]])
        for f in np.linspace(1.0, 0.0, 21):
            if self._side_is_clear(i, pos + f * side * right):
                self._side[i] = f * side
                return
        self._side[i] = 0.0

    def _retreat(self, i: int, robot_xy: np.ndarray, robot_step: np.ndarray, dt: float) -> bool:
        """Step back from a robot closing in (see the class docstring); True if stepped."""
        p = self.people[i]
        rel = self._state[i, :2] - robot_xy
        dist = float(np.hypot(rel[0], rel[1]))
        if not (dt > 0 and dist > 1e-9 and dist - self.robot_radius_m - p.radius_m < self.retreat_gap_m):
            return False
        v = robot_step / dt
        if not self._robot_closing_in(i, rel, v):
            return False
        away = self._retreat_direction(rel / dist, rel, v)
        return self._step_back(i, away, robot_xy, dist, dt)

    def _robot_closing_in(self, i: int, rel: np.ndarray, v: np.ndarray) -> bool:
        """Whether the robot, going on as it goes (velocity ``v``), comes within person
        ``i``'s personal space in the next ``retreat_horizon_s`` (a robot standing inside
        it included). A robot passing alongside does not count, though the distance
        shrinks a little as it draws level: a person overtaking it would be held abeam,
        out of its camera's view."""
        vv = float(v @ v)
        tc = min(max(float(rel @ v) / vv, 0.0), self.retreat_horizon_s) if vv > 1e-12 else 0.0
        cpa = float(np.hypot(*(rel - v * tc)))
        return cpa - self.robot_radius_m - self.people[i].radius_m < self.personal_space_m

    def _retreat_direction(self, away: np.ndarray, rel: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Unit direction of a step back: straight ``away`` from the robot, turned out of
        its way (sideways to its motion, on the side the person is on) when it drives
        faster than ``retreat_sideways_mps``; stepping straight back from a robot driving
        at them, a person is pushed along ahead of it, in its blind zone."""
        vv = float(v @ v)
        if vv > self.retreat_sideways_mps**2:
            n = np.array([-v[1], v[0]]) / math.sqrt(vv)
            if float(n @ rel) < 0.0:
                n = -n
            away = away + 2.0 * n
            away = away / float(np.hypot(away[0], away[1]))
        return away

    def _step_back(self, i: int, away: np.ndarray, robot_xy: np.ndarray, dist: float, dt: float) -> bool:
        """Step ``away`` from the robot at ``retreat_speed_mps``, by the first step that
        keeps off the walls and ends farther than ``dist`` from it
        (:meth:`WallClearance.step_back`); True if one did. The body moves from where it
        is, and the route position (s, side) by as much."""
        _, d = self._route_point(i, self._s[i])
        step = self.retreat_speed_mps * dt
        found = self._walls.step_back(self._state[i, :2], self.people[i].radius_m, away, d, step, robot_xy, dist, self.squeeze_m)
        if found is None:
            return False
        cand_s, cand_side, new = found
        self._state[i, :2] = new
        self._s[i] += cand_s
        self._side[i] += cand_side
        return True

    def advance(self, t: float, robot_xy: np.ndarray | None = None) -> np.ndarray:
        """Move everyone to time t (reacting to the robot); returns (n, 3) x, y, heading."""
        dt = max(0.0, t - self._t)
        self._t = t
        rxy, robot_step = self._robot_motion(robot_xy)
        for i in range(len(self.people)):
            if rxy is not None and self._retreat(i, rxy, robot_step, dt):
                continue
            self._move(i, rxy, robot_step, dt)
        return self._state.copy()

    def _robot_motion(self, robot_xy: np.ndarray | None) -> tuple[np.ndarray | None, np.ndarray]:
        """The robot's position (None if not given) and its step since the last call."""
        robot_step = np.zeros(2)
        if robot_xy is None:
            return None, robot_step
        rxy = np.asarray(robot_xy[:2], dtype=np.float64)
        if self._robot_prev is not None:
            robot_step = rxy - self._robot_prev
        self._robot_prev = rxy.copy()
        return rxy, robot_step

    def _move(self, i: int, rxy: np.ndarray | None, robot_step: np.ndarray, dt: float) -> None:
        """Person ``i``'s step: make way for the robot, walk on, keep off the walls, and
        take no step towards the robot's way."""
        p = self.people[i]
        pos, d = self._route_point(i, self._s[i])
        before = (self._s[i], self._side[i])
        target_side, walk = self._make_way(i, pos, d, rxy, dt)
        self._step_sideways(i, pos, d, target_side, dt)
        if walk:
            self._walk_on(i, dt)
        self._keep_off_walls(i)
        # People walk; they do not jump. Where the route turns while the person is
        # stepped aside, the offset point of the next leg lies elsewhere (up to twice
        # the offset away): walk there at walking plus side-stepping speed.
        reach = (p.speed_mps + self.side_speed_mps) * dt
        new = self._place(i)
        gap = new[:2] - self._state[i, :2]
        dist = float(np.hypot(gap[0], gap[1]))
        if dist > reach:
            new[:2] = self._state[i, :2] + gap * (reach / dist)
        if rxy is None:
            self._blocked[i] = 0.0
        elif not self._keeps_clear(i, new, before, rxy, robot_step, dt, reach):
            return
        self._state[i] = new

    def _make_way(self, i: int, pos: np.ndarray, d: np.ndarray, rxy: np.ndarray | None, dt: float) -> tuple[float, bool]:
        """The side offset person ``i`` heads for and whether they walk on: with the robot
        ahead within ``notice_m`` they step aside and wait while it is within ``pause_m``
        (at most ``max_wait_s``), staying aside until it is ``clear_behind_m`` behind."""
        target_side, walk, noticed = 0.0, True, False
        if rxy is not None:
            rel = rxy - pos
            ahead = float(rel @ d)
            across = float(rel[0] * d[1] - rel[1] * d[0])  # > 0: robot to the person's right
            aside = abs(self._side[i]) > 0.05
            passing = aside and -self.clear_behind_m < ahead <= 0.0
            # Once aside, a wider lateral window: at its edge the person stepped in and
            # out by a step each frame.
            if (0.0 < ahead < self.notice_m or passing) and abs(across - self._side[i]) < (1.5 if aside else 1.0):
                # Stay on the side of the robot they are on (the robot weaves about the
                # same centreline), and stay aside until it is clear_behind_m behind.
                target_side = self.step_aside_m if self._side[i] - across >= 0 else -self.step_aside_m
                walk = ahead > self.pause_m or ahead <= 0.0 or abs(across - self._side[i]) > 0.7 or self._waited[i] > self.max_wait_s
                noticed = True
        # The wait runs while the robot is there, so after max_wait_s they walk on
        # (reset at the first step, it had them creep past a step every 2 s).
        self._waited[i] = self._waited[i] + dt if noticed and (not walk or self._waited[i] > 0) else 0.0
        return target_side, walk

    def _step_sideways(self, i: int, pos: np.ndarray, d: np.ndarray, target_side: float, dt: float) -> None:
        """Move the side offset towards ``target_side`` at ``side_speed_mps``, unless that
        takes the person nearer than 5 cm to a wall (moving back towards the route always goes)."""
        step = float(np.clip(target_side - self._side[i], -self.side_speed_mps * dt, self.side_speed_mps * dt))
        if step:
            right = np.array([d[1], -d[0]])
            new_side = self._side[i] + step
            if self._side_is_clear(i, pos + new_side * right) or abs(new_side) < abs(self._side[i]):
                self._side[i] = new_side

    def _walk_on(self, i: int, dt: float) -> None:
        """Walk along the route; at the end of a back-and-forth route, turn round on the
        spot: stepped aside to the right going out is to the left coming back (keeping
        the right hand, it would be a diagonal walk across the corridor, into a robot there)."""
        route = self._routes[i]
        leg = route.leg(self._s[i])
        self._s[i] += self.people[i].speed_mps * dt
        if route.leg(self._s[i]) != leg:
            self._side[i] = -self._side[i]

    def _keeps_clear(
        self, i: int, new: np.ndarray, before: tuple[float, float], rxy: np.ndarray, robot_step: np.ndarray, dt: float, reach: float
    ) -> bool:
        """Whether person ``i`` may step to ``new``: not closer than the personal space to
        the robot's way for the next ``anticipate_s`` (``pass_gap_m`` from a robot on the
        move: passing it 5 cm abeam, an overtaker is out of its view when it turns),
        unless it takes them no closer. If not, they take a part of the step that keeps
        clear (``_part_step``) or stay put; False then, the step handled."""
        p = self.people[i]
        moving = dt > 0 and float(np.hypot(*robot_step)) > self.moving_mps * dt
        keep = self.robot_radius_m + p.radius_m + (max(self.personal_space_m, self.pass_gap_m) if moving else self.personal_space_m)
        ahead_xy = rxy + robot_step * (self.anticipate_s / dt) if dt > 0 else rxy
        d_new = _segment_distance(new[:2], rxy, ahead_xy)
        d_old = _segment_distance(self._state[i, :2], rxy, ahead_xy)
        if d_new < keep and d_new < d_old:
            self._part_step(i, before, rxy, ahead_xy, min(keep, d_old), reach, dt)
            return False
        if d_new > keep + self.clear_of_robot_m:
            self._blocked[i] = 0.0
        return True

    def _part_step(
        self, i: int, before: tuple[float, float], rxy: np.ndarray, ahead_xy: np.ndarray, min_gap: float, reach: float, dt: float
    ) -> None:
        """The walk alone (stepped aside as before: overtaking the robot) or the side step
        alone, whichever keeps ``min_gap`` from the robot's way; else stay put, held up
        (turning back after ``max_blocked_s``)."""
        walked, side = self._s[i], self._side[i]
        for cand in ((walked, before[1]), (before[0], side)):
            if cand == before or cand == (walked, side):
                continue
            self._s[i], self._side[i] = cand
            alt = self._place(i)
            if float(np.hypot(*(alt[:2] - self._state[i, :2]))) <= reach and _segment_distance(alt[:2], rxy, ahead_xy) >= min_gap:
                self._state[i] = alt
                break
        else:
            self._s[i], self._side[i] = before
            self._blocked[i] += dt
        if self._blocked[i] > self.max_blocked_s:
            self._turn_back(i)
            self._blocked[i] = 0.0

    def positions(self) -> np.ndarray:
        """(n, 3) x, y, heading of each person as of the last :meth:`update`."""
        return self._state.copy()

    def update(self, data: mujoco.MjData, t: float, robot_xy: np.ndarray | None = None) -> None:
        """Advance to time t and write the mocap poses."""
        if not len(self.people):
            return
        pos = self.advance(t, robot_xy)
        for i, mid in enumerate(self.mocap_ids):
            data.mocap_pos[mid, :2] = pos[i, :2]
            data.mocap_quat[mid] = _yaw_quat(pos[i, 2])
