"""A person's route as arc-length geometry (:class:`RoutePath`).

People walk their routes by arc length ``s``: back and forth (``s`` runs on past the end
and comes back, one leg out and one back) or round a loop. Where a person is and which way
they face at any ``s`` depends only on the route, so it is kept apart from how they react
to the robot (:class:`sim.simulator.actors.PeopleController`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class RoutePath:
    """A route's points (closed for a loop), the arc length at each, and whether it loops."""

    pts: np.ndarray
    cum: np.ndarray
    loop: bool

    @classmethod
    def of(cls, route: Sequence[tuple[float, float]], loop: bool) -> RoutePath:
        """The path of a person's ``route`` (waypoints), walked back and forth or, with
        ``loop``, round and back to its first point."""
        pts = np.asarray(route, dtype=np.float64)
        if loop:
            pts = np.vstack([pts, pts[:1]])
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        return cls(pts, np.concatenate([[0.0], np.cumsum(seg)]), loop)

    @property
    def length(self) -> float:
        """The route's length (one way, or once round the loop)."""
        return self.cum[-1]

    def point(self, s: float) -> tuple[np.ndarray, np.ndarray]:
        """Position and unit walking direction at arc length s (ping-pong or loop)."""
        pts, cum = self.pts, self.cum
        total = cum[-1]
        if total <= 0:
            return pts[0].copy(), np.array([1.0, 0.0])
        direction = 1.0
        if self.loop:
            s = s % total
        else:
            s = s % (2 * total)
            if s > total:
                s, direction = 2 * total - s, -1.0
        k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(cum) - 2))
        seg_len = cum[k + 1] - cum[k]
        a = (s - cum[k]) / seg_len if seg_len > 0 else 0.0
        d = pts[k + 1] - pts[k]
        n = float(np.hypot(d[0], d[1]))
        return pts[k] + a * d, (direction * d / n if n > 0 else np.array([1.0, 0.0]))

    def leg(self, s: float) -> int:
        """Which way a back-and-forth route is walked at arc length s: 0 out, 1 back
        (always 0 on a loop)."""
        total = self.cum[-1]
        if self.loop or total <= 0:
            return 0
        return int(math.floor(s / total)) % 2

    def turned_back(self, s: float) -> float | None:
        """The arc length of the same place walked the other way (None on a loop or an
        empty route, where nobody turns back)."""
        total = self.cum[-1]
        if self.loop or total <= 0:
            return None
        return 2.0 * total - s % (2.0 * total)
