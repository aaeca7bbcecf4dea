"""Unmapped objects: furniture (static primitive geoms) and people (kinematic walkers).

Neither is in the vector map, so to the localization they are clutter, and to the
obstacle avoidance they are obstacles: exactly the paper's setting (seed 000, VI).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from autonomy.errors import InputError
from sim.robot import COLL_PEOPLE, COLL_ROBOT, COLL_STATIC

FURNITURE_KINDS = ("table", "chair", "box", "cabinet")

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


def _yaw_quat(yaw: float) -> list[float]:
    return [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]


def add_furniture(spec: mujoco.MjSpec, items: tuple[Furniture, ...]) -> None:
    """Add each piece as a static body of primitive geoms named ``furniture_<i>``."""
    kw = dict(contype=COLL_STATIC, conaffinity=COLL_ROBOT, group=1)
    for i, f in enumerate(items):
        lx, ly, h = f.dims
        b = spec.worldbody.add_body(name=f"furniture_{i}", pos=[f.x, f.y, 0.0], quat=_yaw_quat(f.yaw))
        wood = [0.55, 0.4, 0.25, 1.0]
        box = mujoco.mjtGeom.mjGEOM_BOX
        if f.kind == "table":
            top = 0.03
            b.add_geom(type=box, size=[lx / 2, ly / 2, top / 2], pos=[0, 0, h - top / 2], rgba=wood, **kw)
            leg = 0.025
            for sx in (-1, 1):
                for sy in (-1, 1):
                    b.add_geom(
                        type=box,
                        size=[leg, leg, (h - top) / 2],
                        pos=[sx * (lx / 2 - 2 * leg), sy * (ly / 2 - 2 * leg), (h - top) / 2],
                        rgba=wood,
                        **kw,
                    )
        elif f.kind == "chair":
            seat_h = 0.45
            b.add_geom(type=box, size=[lx / 2, ly / 2, 0.025], pos=[0, 0, seat_h], rgba=wood, **kw)
            b.add_geom(
                type=box, size=[0.02, ly / 2, (h - seat_h) / 2], pos=[-lx / 2 + 0.02, 0, (h + seat_h) / 2], rgba=wood, **kw
            )
            leg = 0.02
            for sx in (-1, 1):
                for sy in (-1, 1):
                    b.add_geom(
                        type=box,
                        size=[leg, leg, seat_h / 2],
                        pos=[sx * (lx / 2 - leg), sy * (ly / 2 - leg), seat_h / 2],
                        rgba=wood,
                        **kw,
                    )
        else:
            color = [0.6, 0.5, 0.35, 1.0] if f.kind == "box" else [0.5, 0.5, 0.55, 1.0]
            b.add_geom(type=box, size=[lx / 2, ly / 2, h / 2], pos=[0, 0, h / 2], rgba=color, **kw)


def add_people(spec: mujoco.MjSpec, people: tuple[Person, ...]) -> None:
    """Add each person as a mocap body ``person_<i>``: a capsule torso and a sphere head."""
    kw = dict(contype=COLL_PEOPLE, conaffinity=COLL_ROBOT, group=1)
    for i, p in enumerate(people):
        b = spec.worldbody.add_body(name=f"person_{i}", mocap=True, pos=[p.route[0][0], p.route[0][1], 0.0])
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


@dataclass
class PeopleController:
    """Moves the people's mocap bodies along their routes as simulated time passes."""

    people: tuple[Person, ...]
    mocap_ids: np.ndarray
    _cum: list[np.ndarray] = field(default_factory=list)
    _pts: list[np.ndarray] = field(default_factory=list)

    @classmethod
    def from_model(cls, model: mujoco.MjModel, people: tuple[Person, ...]) -> PeopleController:
        ids = []
        for i in range(len(people)):
            bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"person_{i}")
            ids.append(model.body_mocapid[bid])
        ctl = cls(people=people, mocap_ids=np.array(ids, dtype=int))
        for p in people:
            pts = np.asarray(p.route, dtype=np.float64)
            if p.loop:
                pts = np.vstack([pts, pts[:1]])
            seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            ctl._pts.append(pts)
            ctl._cum.append(np.concatenate([[0.0], np.cumsum(seg)]))
        return ctl

    def positions(self, t: float) -> np.ndarray:
        """(n, 3) array of x, y, heading of each person at time t."""
        out = np.zeros((len(self.people), 3))
        for i, p in enumerate(self.people):
            pts, cum = self._pts[i], self._cum[i]
            total = cum[-1]
            if total <= 0:
                out[i, :2] = pts[0]
                continue
            s = p.start_offset_m + p.speed_mps * t
            direction = 1.0
            if p.loop:
                s = s % total
            else:
                s = s % (2 * total)
                if s > total:
                    s, direction = 2 * total - s, -1.0
            k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(cum) - 2))
            seg_len = cum[k + 1] - cum[k]
            a = (s - cum[k]) / seg_len if seg_len > 0 else 0.0
            d = pts[k + 1] - pts[k]
            out[i, :2] = pts[k] + a * d
            out[i, 2] = math.atan2(direction * d[1], direction * d[0])
        return out

    def update(self, data: mujoco.MjData, t: float) -> None:
        """Place every person at time t."""
        if not len(self.people):
            return
        pos = self.positions(t)
        for i, mid in enumerate(self.mocap_ids):
            data.mocap_pos[mid, :2] = pos[i, :2]
            data.mocap_quat[mid] = _yaw_quat(pos[i, 2])
