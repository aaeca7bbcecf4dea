"""The plan the navigator follows: a polyline from the pose through graph nodes, measured
along its arc length, with what lies along it (corners, narrow stretches, the edges'
speed limits).

A :class:`Plan` is made by :meth:`autonomy.navigation.route.RoutePlanner.plan` (through
:meth:`Plan.along`) and not changed after: a re-plan makes a new one. Its queries take
an arc length ``s`` (metres from the plan's start) or a point to project on it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from autonomy.common.geometry import point_segment_projection, wrap_angles
from autonomy.navigation.config import NavigatorConfig


@dataclass(frozen=True, eq=False)
class Plan:
    """A plan to ``goal`` (none: no plan) and its geometry along the arc length."""

    cfg: NavigatorConfig
    robot_radius_m: float
    """The robot's radius (the avoidance's): the robot's back is this far behind ``s``."""
    goal: int | None = None
    """The goal node; None without a plan."""
    nodes: list[int] = field(default_factory=list)
    """The plan's graph nodes (the plan runs from the pose to the first of them, then on)."""
    path: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    """The polyline (K, 2), world frame, the pose's position first."""
    cum: np.ndarray = field(default_factory=lambda: np.zeros(1))
    """Arc length at each vertex of ``path``."""
    segments: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    """The plan's segments (x1, y1, x2, y2) (:meth:`project`) ..."""
    seg_len: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """... and their lengths."""
    seg_speed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Each segment's edge ``max_speed`` (inf: none, or no edge)."""
    narrow_s: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    """The plan's narrow stretches (arc lengths from, to)."""
    corners: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """Arc lengths of the vertices where the plan turns by more than ``corner_angle_rad``."""
    shortcuts: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    """The segments that go straight past graph nodes (:mod:`autonomy.navigation.shortcut`)."""

    @classmethod
    def along(
        cls,
        cfg: NavigatorConfig,
        robot_radius_m: float,
        goal: int,
        nodes: list[int],
        pts: np.ndarray,
        edges: Sequence[tuple[int, int] | None],
        edge_speed: Mapping[tuple[int, int], float],
        narrow: Mapping[tuple[int, int], tuple[np.ndarray, np.ndarray]],
        shortcuts: np.ndarray | None = None,
    ) -> Plan:
        """The plan to ``goal`` through ``nodes`` along the points ``pts`` (K, 2) (the pose
        first): ``edges`` names the graph edge (node ids, in the direction driven; None:
        none) each of the K - 1 segments runs along, ``edge_speed`` the edges' speed
        limits and ``narrow`` the narrow edges' narrow stretches (world points from, to);
        ``shortcuts`` are the segments that go straight past nodes. Segments shorter than
        1 um are dropped."""
        seg_len = np.hypot(*np.diff(pts, axis=0).T)
        keep = np.concatenate([[True], seg_len > 1e-6])
        path = pts[keep]
        kept = [ab for ab, k in zip(edges, keep[1:], strict=True) if k]
        seg_speed = np.array([math.inf if ab is None else edge_speed.get(ab, math.inf) for ab in kept])
        seg = np.hypot(*np.diff(path, axis=0).T) if len(path) > 1 else np.zeros(0)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        segments = np.hstack([path[:-1], path[1:]])
        d = segments[:, 2:] - segments[:, :2]
        seg_len = np.sqrt(np.einsum("ij,ij->i", d, d))  # as project's t measures them
        # Narrow stretches in arc length: each edge's stretch put on its segment (on the
        # first, which may start part way along its edge, a stretch behind the pose has
        # negative arc lengths: the robot's back may still be in it).
        spans = []
        for k, ab in enumerate(kept):
            if ab is None or ab not in narrow or seg_len[k] <= 0:
                continue
            u = (path[k + 1] - path[k]) / seg_len[k]
            spans.append([cum[k] + float((p - path[k]) @ u) for p in narrow[ab]])
        narrow_s = np.array(spans, dtype=np.float64).reshape(-1, 2)
        # Corners: inner vertices where the plan turns by more than corner_angle_rad.
        corners = np.zeros(0)
        if len(path) > 2:
            d = np.diff(path, axis=0)
            heading = np.arctan2(d[:, 1], d[:, 0])
            turn = np.abs(wrap_angles(np.diff(heading)))
            corners = cum[1:-1][turn > cfg.corner_angle_rad]
        short = np.zeros((0, 4)) if shortcuts is None else np.asarray(shortcuts, dtype=np.float64).reshape(-1, 4)
        return cls(cfg, robot_radius_m, goal, list(nodes), path, cum, segments, seg_len, seg_speed, narrow_s, corners, short)

    @property
    def length_m(self) -> float:
        return float(self.cum[-1])

    def project(self, xy: np.ndarray) -> float:
        """Arc length of the point of the plan nearest ``xy``."""
        t, dist = point_segment_projection(xy, self.segments)
        k = int(np.argmin(dist))
        return float(self.cum[k] + t[k] * self.seg_len[k])

    def point_at(self, s: float) -> np.ndarray:
        """The plan's point at arc length ``s`` (clamped to the plan)."""
        s = min(max(s, 0.0), float(self.cum[-1]))
        k = min(max(int(np.searchsorted(self.cum, s, side="right")) - 1, 0), len(self.path) - 2)
        L = self.cum[k + 1] - self.cum[k]
        a = 0.0 if L == 0 else (s - self.cum[k]) / L
        return self.path[k] + a * (self.path[k + 1] - self.path[k])

    def remaining_m(self, xy: np.ndarray) -> float:
        """Length of the plan still ahead of ``xy`` (from the plan's point nearest it);
        0 without a plan."""
        if len(self.path) < 2:
            return 0.0
        return float(self.cum[-1]) - self.project(xy)

    def corner_speed_limit(self, s: float) -> float:
        """Speed limit at arc length ``s`` of the plan from its corners: ``corner_speed_mps``
        from ``corner_before_m`` before a corner to ``corner_after_m`` past it, rising
        linearly to the cruise speed over ``corner_ramp_m`` before that; inf when off."""
        cfg = self.cfg
        if cfg.corner_speed_mps <= 0 or not len(self.corners):
            return math.inf
        ahead = self.corners - s
        ahead = ahead[ahead >= -cfg.corner_after_m]
        if not len(ahead):
            return math.inf
        d = float(ahead.min()) - cfg.corner_before_m
        if d <= 0.0:
            return cfg.corner_speed_mps
        if cfg.corner_ramp_m <= 0 or d >= cfg.corner_ramp_m:
            return math.inf
        return cfg.corner_speed_mps + (cfg.cruise_speed_mps - cfg.corner_speed_mps) * d / cfg.corner_ramp_m

    def edge_speed_limit(self, s: float) -> float:
        """The lowest ``max_speed`` of the plan's edges from ``robot_radius_m`` behind arc
        length ``s`` to ``lookahead_m`` ahead of it; inf when off or unlimited."""
        if not self.cfg.edge_speed_limits or not len(self.seg_speed):
            return math.inf
        lo, hi = s - self.robot_radius_m, s + self.cfg.lookahead_m
        on = (self.cum[1:] > lo) & (self.cum[:-1] < hi)
        return float(self.seg_speed[on].min()) if on.any() else math.inf

    def lookahead(self, s: float) -> float:
        """Carrot distance at arc length ``s``: ``narrow_lookahead_m`` from
        ``narrow_before_m`` before a narrow stretch of the plan until ``robot_radius_m``
        past it, else ``lookahead_m``."""
        cfg = self.cfg
        if cfg.narrow_lookahead_m <= 0 or not len(self.narrow_s):
            return cfg.lookahead_m
        lo, hi = s - self.robot_radius_m, s + cfg.narrow_before_m
        on = (self.narrow_s[:, 1] >= lo) & (self.narrow_s[:, 0] <= hi)
        return cfg.narrow_lookahead_m if on.any() else cfg.lookahead_m
