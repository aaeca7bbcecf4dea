"""Any-angle plans: a graph path straightened where the map leaves room.

Navigation graphs made from a floor's walls fill halls with irregular triangulations, so
a route across a hall zigzags from node to node (15-19 degrees of turning a metre on the
real floors of ``../shared/maps``). Each turn costs time, and where the camera sees no
wall the localization dead-reckons on the odometry, whose rotation error grows with
every degree turned. As path smoothers do for grid and graph planners (nav2's smoother
server; Theta*, Nash et al., AAAI 2007), the plan goes straight from a vertex to the
farthest later one it may reach: through a run of plain edges only (a door, a narrow
stretch or an edge with a speed limit below the cruise speed is driven as the graph
lays it), keeping ``shortcut_clearance_m`` from every wall and from what blocked an
edge, and blind for at most ``shortcut_blind_slack_m`` more than the graph's own way
(:func:`autonomy.maps.planner.blind_lengths`), so that coastal navigation keeps its
walls in view.
"""

from __future__ import annotations

import numpy as np

from autonomy.common.geometry import WallIndex, point_segment_distance
from autonomy.maps.planner import BlindSegments


class Shortcuts:
    """Straightens plan polylines among ``walls`` (K, 4): :meth:`straighten`."""

    def __init__(self, walls: np.ndarray, clearance_m: float, blind_slack_m: float, blind: BlindSegments | None) -> None:
        self.walls = WallIndex(np.asarray(walls, dtype=np.float64).reshape(-1, 4))
        self.clearance_m = float(clearance_m)
        self.blind_slack_m = float(blind_slack_m)
        self.blind = blind
        """The blind metres of a segment (None: coastal navigation off, not compared)."""

    def straighten(
        self, pts: np.ndarray, plain: np.ndarray, keep_off: np.ndarray, keep_off_m: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """The vertices kept of the polyline ``pts`` (K, 2), greedily from the first: from
        each, the farthest later vertex reached through segments all ``plain`` (K - 1,)
        whose straight line keeps the clearance from the walls and ``keep_off_m`` from
        the points ``keep_off`` (M, 2), and is not blinder than the way it replaces by more
        than the slack. Returns (indices of the kept vertices, first and last included;
        per kept segment, whether it replaces more than one segment)."""
        pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        k = len(pts)
        if k < 3:
            return np.arange(k), np.zeros(max(0, k - 1), dtype=bool)
        seg = np.hstack([pts[:-1], pts[1:]])
        cum_blind = None
        if self.blind is not None:
            cum_blind = np.concatenate([[0.0], np.cumsum(self.blind.lengths(seg))])
        keep, short = [0], []
        i = 0
        while i < k - 1:
            end = i
            while end < k - 1 and plain[end]:
                end += 1
            best = i + 1
            if end - i >= 2:
                js = np.arange(end, i + 1, -1)  # the farthest first
                lines = np.hstack([np.repeat(pts[i][None, :], len(js), axis=0), pts[js]])
                ok = self.walls.clearances(lines, self.clearance_m) >= self.clearance_m
                if len(keep_off) and ok.any():
                    ok &= point_segment_distance(keep_off, lines).min(axis=0) >= keep_off_m
                for j, line in zip(js[ok], lines[ok], strict=True):
                    if cum_blind is None or self.blind.lengths(line)[0] <= cum_blind[j] - cum_blind[i] + self.blind_slack_m:
                        best = int(j)
                        break
            keep.append(best)
            short.append(best > i + 1)
            i = best
        return np.asarray(keep), np.asarray(short, dtype=bool)
