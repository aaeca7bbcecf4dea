"""The walls as people keep off them, and the step back from a robot along them
(:class:`WallClearance`).

People are not stopped by walls (only the robot is): they keep off them by rule. This
module holds that geometry: a body's distance to the nearest wall, whether a place keeps a
margin from every wall, and which step back from a robot closing in keeps one, down to
sliding along a wall. When to step back, and which way, is the people's manners
(:class:`sim.simulator.actors.PeopleController`).
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import point_segment_distance

#: The margin people keep from walls where they can.
WALL_MARGIN_M = 0.05

_FAN = tuple(math.radians(a) for a in (30, -30, 60, -60, 90, -90, 120, -120, 150, -150, 180))
"""Directions (from straight away) a person stepping back from the robot tries last."""


def retreat_steps(away: np.ndarray, d: np.ndarray, right: np.ndarray, step: float) -> list[tuple[float, float]]:
    """The steps back a person tries, in order, as (along the route, to its right).

    Straight away; else along the route, a full step (with a wall beside, the along-route
    part of a step straight away alone leaves a person pushed along ahead of the robot);
    else only sideways, a full step (the route ends or bends right behind them); failing
    all three, any other way, the nearest to straight away first (``_FAN``): at the end
    of a door frame the three can all lead towards the frame.
    """
    ds, dside = step * float(away @ d), step * float(away @ right)
    cands = [(ds, dside), (math.copysign(step, ds), 0.0), (0.0, math.copysign(step, dside))]
    for a in _FAN:
        u = (math.cos(a) * away[0] - math.sin(a) * away[1], math.sin(a) * away[0] + math.cos(a) * away[1])
        cands.append((step * (u[0] * d[0] + u[1] * d[1]), step * (u[0] * right[0] + u[1] * right[1])))
    return cands


class WallClearance:
    """The walls (N, 4) people keep off; none: everywhere is clear."""

    def __init__(self, walls: np.ndarray | None = None) -> None:
        self.walls = np.zeros((0, 4)) if walls is None else np.asarray(walls, dtype=np.float64)

    def distance(self, pos: np.ndarray) -> float:
        """Distance from a body's centre to the nearest wall (inf without walls)."""
        if not len(self.walls):
            return math.inf
        return float(point_segment_distance(pos, self.walls).min())

    def is_clear(self, pos: np.ndarray, radius_m: float, margin_m: float = WALL_MARGIN_M) -> bool:
        """Whether a body of ``radius_m`` at ``pos`` keeps ``margin_m`` from every wall."""
        return self.distance(pos) > radius_m + margin_m

    def direction(self, pos: np.ndarray) -> np.ndarray | None:
        """Unit direction of the wall nearest ``pos`` (None without walls)."""
        if not len(self.walls):
            return None
        w = self.walls[int(np.argmin(point_segment_distance(pos, self.walls)))]
        u = w[2:4] - w[0:2]
        n = float(np.hypot(u[0], u[1]))
        return u / n if n > 1e-12 else None

    def step_back(
        self, here: np.ndarray, radius_m: float, away: np.ndarray, d: np.ndarray, step: float,
        robot_xy: np.ndarray, dist: float, squeeze_m: float,
    ) -> tuple[float, float, np.ndarray] | None:
        """The first step of :func:`retreat_steps` (``away`` from the robot, ``step`` long,
        the route's direction ``d`` there) from ``here`` that keeps 5 cm from the walls and
        ends farther than ``dist`` from the robot: (along the route, to its right, the new
        body position); None if none did. Wedged where none keeps 5 cm (a door frame
        beside, the robot turning into the door), a person squeezes along the wall,
        ``squeeze_m`` from it: keeping the 5 cm, such a person would stand still while the
        robot, which cannot see them, drives into them.

        The step moves the body from where it is, and the route position (s, side) by as
        much; walking on reconciles the two. Placing the body at the new route position
        instead, a person whose body lags it (walking to the next leg's offset after a
        corner) could take no step at all: every one would be a jump.

        A body already closer than ``squeeze_m`` to a wall (it lagged its route position
        while the robot held it up, and stands in the end of a door's frame) can end no
        step ``squeeze_m`` from it; it takes the first step that goes no deeper into the
        wall. Else it would stand still there while the robot, which cannot see it beside
        it, drives out of the door into it.

        Failing every step of :func:`retreat_steps`, a person slides along the nearest
        wall, either way: pressed against a wall by a robot closing in at a slant, each
        step of the 30 degree fan either goes into the wall or comes nearer the robot, and
        the one way out, along the wall, is none of them.
        """
        right = np.array([d[1], -d[0]])
        inside = self.distance(here)
        cands = retreat_steps(away, d, right, step)
        found = self._first_step(here, radius_m, cands, d, right, inside, robot_xy, dist, squeeze_m)
        if found is not None:
            return found
        along = self.direction(here)
        if along is None:
            return None
        along = along if float(along @ away) >= 0.0 else -along
        cands = [(step * float(u @ d), step * float(u @ right)) for u in (along, -along)]
        return self._first_step(here, radius_m, cands, d, right, inside, robot_xy, dist, squeeze_m, 1e-9)

    def _first_step(
        self,
        here: np.ndarray,
        radius_m: float,
        cands: list[tuple[float, float]],
        d: np.ndarray,
        right: np.ndarray,
        inside: float,
        robot_xy: np.ndarray,
        dist: float,
        squeeze_m: float,
        tol: float = 0.0,
    ) -> tuple[float, float, np.ndarray] | None:
        """The first of ``cands`` (along the route, to its right) that keeps 5 cm from
        the walls, else ``squeeze_m``, else (a body already that close) goes no deeper
        (``tol``: rounding allowed, for steps along a wall), and ends farther than ``dist``
        from the robot (see :meth:`step_back`)."""
        tries = [(m, c) for m in (WALL_MARGIN_M, squeeze_m) for c in cands]
        if inside <= radius_m + squeeze_m:
            tries += [(None, c) for c in cands]
        for margin, (cand_s, cand_side) in tries:
            new = here + cand_s * d + cand_side * right
            if margin is None:
                if self.distance(new) < inside - tol:
                    continue
            elif not self.is_clear(new, radius_m, margin):
                continue
            if float(np.hypot(new[0] - robot_xy[0], new[1] - robot_xy[1])) > dist:
                return cand_s, cand_side, new
        return None
