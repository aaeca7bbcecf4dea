"""Global relocalization on a vector map: where is the robot when its belief is lost?

When the health monitor (:mod:`autonomy.localization.health`) says lost, or at start-up with no known
pose, the robot stops and turns in place, and this module collects what the camera sees
into a **scan**: the down-projected plane points of every frame, placed through dead
reckoning (over one turn in place it drifts by about a degree) and thinned to one point
per ``scan_cell_m`` cell. A panorama is far less ambiguous than one 58 degree frame.

The scan is then matched against the whole map (ours; the papers re-localized by hand):

1. **Coarse search.** Hypotheses on a grid over the map's free space (every
   ``grid_step_m`` where the robot fits, :class:`autonomy.maps.freespace.FreeSpace`) times
   ``heading_step_deg`` headings; each scores the mean robust cost
   ``min(d^2, c^2) / c^2`` of a subsample of the scan's points, ``d`` the distance from
   the point to the nearest wall, read from the free space's distance transform (a
   likelihood field: one table look-up per point, no ray casting). People and furniture
   cost the same at every hypothesis; the cost saturates so they cannot dominate. The
   best are re-ranked with their sight through walls (below) before the distinct ones
   are refined: a room's corner fits hundreds of places on cost alone.
2. **Modes.** The best hypotheses are refined coarse to fine on the same field with all
   scan points, and **scored**: the cost plus ``through_weight`` times the fraction of
   the scan's points that the mode sees through the map's walls (each point's ray
   from where the camera stood when it saw it, marched over the distance transform; a
   point counts when it lies behind a wall its ray crosses by more than ``through_m``
   along the ray and ``through_depth_m`` from the wall's line, so that drift does not
   count a wall seen at a glancing angle as seen through).
   The likelihood field alone favours places with many walls: a hall's furniture fits
   some office's walls better than the hall's own few. Clutter can only hide walls,
   never show what lies behind them, so sight through walls rules such places out.
   So does the floor seen far away (:mod:`autonomy.perception.floor_rays`): the score adds
   ``floor_weight`` times the fraction of the sight lines to it that cross the mode's
   walls, away from their ends (dead reckoning's drift takes sight lines through a door
   across its jambs).
   The best-scored, at least ``mode_separation_m`` or ``mode_separation_deg`` apart
   (non-maximum suppression), are the modes.
3. **Decision.** The best mode is accepted when it explains the scan
   (score at most ``accept_cost``, or at most ``accept_lead_cost`` and leading every
   other mode by ``accept_lead``), the latest frame does not see through the map's walls
   from it (:func:`autonomy.localization.health.explain_points` on its visible scene lines), and no
   other mode comes within ``accept_margin`` of its score per point nor within
   ``accept_margin_points`` over the whole scan. Otherwise the modes are kept
   and the robot looks on (a symmetric corridor is resolved by what it sees next, not by
   a guess). The belief the robot had before it was lost competes as one more mode, so a
   false alarm ends where it began.
"""


from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from autonomy.common.geometry import points_from_frame, points_in_frame, sensor_view, wrap_angle
from autonomy.localization.health import explain_points
from autonomy.localization.likelihood_field import _cost, _grid_costs, _refine
from autonomy.localization.relocalization_config import RelocalizationConfig
from autonomy.localization.sight_through_walls import (
    SEGMENT_INDEX_CELL_M,
    _through_counts,
    segment_index,
)
from autonomy.maps.freespace import FreeSpace


@dataclass(frozen=True)
class Mode:
    """One hypothesis of the robot's pose after the search."""

    pose: np.ndarray
    """(x, y, theta) in the map."""
    cost: float
    """Mean robust cost of the scan there (0 = every point on a wall, 1 = none near one;
    each of the scan's pieces at its own refinement, :meth:`GlobalLocalizer.piece_scores`)."""
    through: float = math.nan
    """Fraction of the latest frame's points seen through a mapped wall from there."""
    scan_through: float = math.nan
    """Fraction of the scan's points seen through a mapped wall from there (NaN: the
    scan's viewpoints were not given)."""
    score: float = math.nan
    """What the modes are ranked and decided by: ``cost`` plus ``through_weight`` times
    ``scan_through`` plus ``floor_weight`` times ``floor_through`` (each term left out
    when NaN)."""
    floor_through: float = math.nan
    """Fraction of the floor points seen while looking whose sight line crosses a mapped
    wall from there, ``floor_jamb_m`` or more from its ends (NaN: no floor points given)."""

    def __post_init__(self) -> None:
        if math.isnan(self.score):
            object.__setattr__(self, "score", self.cost)


@dataclass(frozen=True)
class SearchResult:
    """What one search found and decided."""

    modes: tuple[Mode, ...]
    """Distinct modes, best first."""
    accepted: Mode | None
    """The mode accepted (None: undecided, keep looking)."""
    reason: str
    """Why it was accepted or not."""
    hypotheses: int
    """Coarse hypotheses scored."""


# --------------------------------------------------------------------------- the scan


class Scan:
    """Observation points gathered while looking, in the dead-reckoning frame, one per
    ``cell_m`` cell (the newest), at most ``max_points``, each with where the camera stood
    and when it saw it."""

    def __init__(self, cell_m: float, max_points: int, sensor_xy: tuple[float, float] = (0.0, 0.0), floor_cell_m: float = 0.25) -> None:
        """``sensor_xy``: where the camera sits in the robot frame (its rays start there);
        ``floor_cell_m``: the cell of the floor points kept."""
        self.cell_m = cell_m
        self.floor_cell_m = floor_cell_m
        self.max_points = max_points
        self.sensor_xy = np.asarray(sensor_xy, dtype=np.float64).reshape(2)
        self.clear()

    def clear(self) -> None:
        self.points = np.zeros((0, 2))
        self.origins = np.zeros((0, 2))
        """Where the camera stood (dead reckoning) when it saw each point."""
        self.times = np.zeros(0)
        """When it saw each point (s)."""
        self.floor = np.zeros((0, 2))
        """Floor points seen (:mod:`autonomy.perception.floor_rays`), one per cell, the newest ..."""
        self.floor_origins = np.zeros((0, 2))
        """... and where the camera stood when it saw each."""
        self.turned_rad = 0.0
        self.travelled_m = 0.0
        self._last: np.ndarray | None = None
        self.frames = 0

    def add(self, odom_pose: np.ndarray, pts_robot: np.ndarray, t: float, floor_robot: np.ndarray | None = None) -> None:
        """Add one frame's points (robot frame) seen at ``odom_pose`` (dead reckoning) at
        time ``t``, and the floor points it saw (robot frame, :mod:`autonomy.perception.floor_rays`)."""
        p = np.asarray(odom_pose, dtype=np.float64)
        if self._last is not None:
            self.turned_rad += abs(wrap_angle(float(p[2] - self._last[2])))
            self.travelled_m += math.hypot(float(p[0] - self._last[0]), float(p[1] - self._last[1]))
        self._last = p.copy()
        self.frames += 1
        at = points_from_frame(p, self.sensor_xy[None, :])
        if floor_robot is not None and len(floor_robot):
            f = points_from_frame(p, np.asarray(floor_robot, dtype=np.float64).reshape(-1, 2))
            keep = self._newest_per_cell(f, self.floor, self.floor_cell_m)
            self.floor = np.vstack([f, self.floor])[keep]
            self.floor_origins = np.vstack([np.broadcast_to(at, f.shape), self.floor_origins])[keep]
        q = np.asarray(pts_robot, dtype=np.float64).reshape(-1, 2)
        if not len(q):
            return
        w = points_from_frame(p, q)
        keep = self._newest_per_cell(w, self.points, self.cell_m)
        self.points = np.vstack([w, self.points])[keep]
        self.origins = np.vstack([np.broadcast_to(at, w.shape), self.origins])[keep]
        self.times = np.concatenate([np.full(len(w), float(t)), self.times])[keep]

    def _newest_per_cell(self, new: np.ndarray, old: np.ndarray, cell: float) -> np.ndarray:
        """Indices into ``new`` stacked on ``old`` (newest first) that keep the first point
        of each ``cell`` cell, in order, at most ``max_points``."""
        key = np.floor(np.vstack([new, old]) / cell).astype(np.int64)
        _, first = np.unique(key[:, 0] * 1_000_003 + key[:, 1], return_index=True)
        first.sort()
        return first[: self.max_points]

    def in_robot_frame(self, odom_pose: np.ndarray) -> np.ndarray:
        """The scan relative to the robot now (at ``odom_pose``)."""
        return points_in_frame(odom_pose, self.points)

    def recent_in_robot_frame(self, odom_pose: np.ndarray, since_t: float) -> np.ndarray:
        """The points seen at ``since_t`` or later, relative to the robot now."""
        return points_in_frame(odom_pose, self.points[self.times >= since_t])

    def origins_in_robot_frame(self, odom_pose: np.ndarray) -> np.ndarray:
        """Where each point was seen from, relative to the robot now."""
        return points_in_frame(odom_pose, self.origins)

    def floor_in_robot_frame(self, odom_pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The floor points seen and where each was seen from, relative to the robot now."""
        return points_in_frame(odom_pose, self.floor), points_in_frame(odom_pose, self.floor_origins)


# --------------------------------------------------------------------------- the search


class GlobalLocalizer:
    """The coarse search, modes and decision of the module docstring, on one map."""

    def __init__(
        self, free_space: FreeSpace, robot_radius_m: float, cfg: RelocalizationConfig = RelocalizationConfig(),
        segments: np.ndarray | None = None, sensor_xy: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        """``segments``: the map's walls the free space was built from, to confirm the
        scan's sight through walls exactly (without them the grid decides, and a ray
        through a door beside its jamb can count as seen through the wall).
        ``sensor_xy``: where the camera sits in the robot frame; the latest frame's rays
        start there."""
        self.cfg = cfg
        self.sensor_xy = np.asarray(sensor_xy, dtype=np.float64).reshape(2)
        self.fs = free_space
        self.dist = np.ascontiguousarray(free_space.dist, dtype=np.float32)
        self.origin = free_space.origin
        self.inv_cell = 1.0 / free_space.cell_m
        ny, nx = self.dist.shape
        ic = SEGMENT_INDEX_CELL_M
        self._ishape = (max(1, int(math.ceil(ny * free_space.cell_m / ic))), max(1, int(math.ceil(nx * free_space.cell_m / ic))))
        if segments is None:
            self._seg, self._start, self._ids = np.zeros((0, 4)), np.zeros(1, np.int64), np.zeros(0, np.int64)
        else:
            self._seg = np.ascontiguousarray(segments, dtype=np.float64).reshape(-1, 4)
            self._start, self._ids = segment_index(self._seg, self.origin[0], self.origin[1], ic, *self._ishape)
        rows, cols = free_space.free_cells(robot_radius_m, region=None, cache=False)
        step = max(1, int(round(cfg.grid_step_m / free_space.cell_m)))
        keep = (rows % step == step // 2) & (cols % step == step // 2)
        self.candidates = np.ascontiguousarray(free_space.centres(rows[keep], cols[keep]))
        k = max(1, int(round(360.0 / cfg.heading_step_deg)))
        self.headings = np.arange(k) * (2.0 * math.pi / k)

    def cost(self, pose: np.ndarray, pts: np.ndarray, robust_m: float | None = None) -> float:
        """Mean robust cost of robot-frame points at a pose (the likelihood field)."""
        r = self.cfg.fine_robust_m if robust_m is None else robust_m
        p = np.asarray(pose, dtype=np.float64)
        return float(
            _cost(self.dist, self.origin[0], self.origin[1], self.inv_cell, p[0], p[1], math.cos(p[2]), math.sin(p[2]),
                  np.ascontiguousarray(pts, dtype=np.float64), r * r)
        )

    def scan_through(self, pose: np.ndarray, origins: np.ndarray, pts: np.ndarray) -> float:
        """Fraction of robot-frame points ``pts``, seen from robot-frame ``origins``, that
        lie behind a wall their ray crosses at ``pose``: more than ``through_m`` along
        the ray and ``through_depth_m`` from the wall's line."""
        return float(self.scan_through_at(np.asarray(pose, dtype=np.float64)[None, :], origins, pts)[0])

    def scan_through_at(
        self, poses: np.ndarray, origins: np.ndarray, pts: np.ndarray, margin_m: float | None = None,
        depth_m: float | None = None, end_m: float = 0.0,
    ) -> np.ndarray:
        """:meth:`scan_through` at each of ``poses`` (N, 3), with the margins ``margin_m``
        along the ray (default ``through_m``) and ``depth_m`` from the wall's line
        (default ``through_depth_m``); a wall counts only where it is crossed at least
        ``end_m`` from its segment's ends (with the map's segments given)."""
        poses = np.ascontiguousarray(poses, dtype=np.float64).reshape(-1, 3)
        pts = np.ascontiguousarray(pts, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(len(poses), dtype=np.int64)
        if not len(pts):
            return out.astype(np.float64)
        _through_counts(
            self.dist, self.origin[0], self.origin[1], self.inv_cell, poses,
            np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 2), pts,
            self.cfg.through_m if margin_m is None else float(margin_m),
            self.cfg.through_depth_m if depth_m is None else float(depth_m),
            self._seg, self._start, self._ids, self.origin[0], self.origin[1], 1.0 / SEGMENT_INDEX_CELL_M, *self._ishape,
            float(end_m), out,
        )
        return out / len(pts)

    def warm(self) -> None:
        """Run each kernel of :meth:`search` once on one hypothesis and a few points, so
        that numba loads them (and starts its thread pool, which the search's parallel
        kernels are the first of a run to use) before the first alarm rather than at it:
        a long run's memory then steps at its start, not at its first relocalization."""
        if not len(self.candidates):
            return
        pts = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.5]])
        rot = np.empty((1, 3, 2))  # writeable, as the search's: a read-only array is another signature
        rot[0] = pts
        _grid_costs(self.dist, self.origin[0], self.origin[1], self.inv_cell, self.candidates[:1], rot, 1.0, np.empty((1, 1)))
        pose = np.array([self.candidates[0, 0], self.candidates[0, 1], 0.0])
        _refine(self.dist, self.origin[0], self.origin[1], self.inv_cell, pose.copy(), pts, 1.0, 0.1, 0.1, 1)
        self.cost(pose, pts)
        self.scan_through_at(pose[None, :], np.zeros((3, 2)), pts)

    def _coarse_subsample(self, n: int) -> np.ndarray:
        """Indices of the even subsample of ``n`` scan points the coarse pass scores."""
        return np.linspace(0, n - 1, min(n, self.cfg.coarse_points)).astype(np.int64)

    def coarse(self, pts: np.ndarray) -> np.ndarray:
        """Costs (H, K) of every coarse hypothesis for robot-frame points ``pts``."""
        cfg = self.cfg
        n = len(pts)
        sub = pts[self._coarse_subsample(n)] if n else pts
        c, s = np.cos(self.headings), np.sin(self.headings)
        rot = np.empty((len(self.headings), len(sub), 2))
        rot[:, :, 0] = c[:, None] * sub[None, :, 0] - s[:, None] * sub[None, :, 1]
        rot[:, :, 1] = s[:, None] * sub[None, :, 0] + c[:, None] * sub[None, :, 1]
        out = np.empty((len(self.candidates), len(self.headings)))
        _grid_costs(self.dist, self.origin[0], self.origin[1], self.inv_cell, self.candidates, rot, cfg.coarse_robust_m**2, out)
        return out

    def _distinct(self, poses: np.ndarray, order: np.ndarray, limit: int) -> list[int]:
        cfg = self.cfg
        sep_rad = math.radians(cfg.mode_separation_deg)
        picked: list[int] = []
        for i in order:
            p = poses[i]
            if all(
                math.hypot(p[0] - poses[j][0], p[1] - poses[j][1]) >= cfg.mode_separation_m
                or abs(wrap_angle(float(p[2] - poses[j][2]))) >= sep_rad
                for j in picked
            ):
                picked.append(int(i))
                if len(picked) >= limit:
                    break
        return picked

    def search(
        self, pts: np.ndarray, frame_pts: np.ndarray | None = None, scene_lines=None, prior: np.ndarray | None = None,
        origins: np.ndarray | None = None, times: np.ndarray | None = None, floor: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> SearchResult:
        """Match robot-frame scan points ``pts`` (seen from ``origins`` at ``times``)
        against the whole map: coarse search, then :meth:`rescore` of the best distinct
        hypotheses (``prior``, the belief before the robot was lost, competes with them).
        ``floor``: robot-frame floor points seen and where each was seen from
        (:meth:`Scan.floor_in_robot_frame`)."""
        cfg = self.cfg
        pts = np.ascontiguousarray(pts, dtype=np.float64).reshape(-1, 2)
        if len(pts) < cfg.min_scan_points:
            return SearchResult((), None, f"{len(pts)} scan points (need {cfg.min_scan_points})", 0)
        costs = self.coarse(pts)
        flat = np.argsort(costs, axis=None)[: cfg.coarse_seeds]
        h, k = np.unravel_index(flat, costs.shape)
        seeds = np.column_stack([self.candidates[h], self.headings[k]])
        order = np.arange(len(seeds))
        if origins is not None:
            # A few walls seen (a room's corner) fit hundreds of places on cost alone; the
            # coarse hypotheses that see through walls drop back before the distinct
            # ones are picked (with the coarse pass's saturation as the margin: a coarse
            # hypothesis is up to half a grid step off).
            sub = self._coarse_subsample(len(pts))
            margin = max(cfg.through_m, cfg.coarse_robust_m)
            thr = self.scan_through_at(seeds, np.asarray(origins, dtype=np.float64)[sub], pts[sub], margin)
            rank = costs.ravel()[flat] + cfg.through_weight * thr
            if self._uses_floor(floor):
                assert floor is not None
                fsub = self._coarse_subsample(len(floor[0]))
                crossing = self.scan_through_at(seeds, floor[1][fsub], floor[0][fsub], margin, end_m=cfg.floor_jamb_m)
                rank = rank + cfg.floor_weight * crossing
            order = np.argsort(rank, kind="stable")
        by_cost = np.arange(len(seeds))  # the coarse costs' order
        if prior is not None:
            seeds = np.vstack([np.asarray(prior, dtype=np.float64)[None, :], seeds])
            order = np.concatenate([[0], order + 1])
            by_cost = by_cost + 1
        picked = self._distinct(seeds, order, 2 * cfg.modes)
        if origins is not None and cfg.cost_seeds > 0:
            chosen = set(picked)
            # Not thinned first: two seeds a grid step apart can fall into different
            # basins (a doubled wall line), and the refinement tells which is the place.
            picked += [int(i) for i in by_cost[: cfg.cost_seeds] if int(i) not in chosen]
        res = self.rescore(seeds[picked], pts, frame_pts, scene_lines, origins, times, floor)
        return SearchResult(res.modes, res.accepted, res.reason, int(costs.size))

    def _uses_floor(self, floor: tuple[np.ndarray, np.ndarray] | None) -> bool:
        return floor is not None and len(floor[0]) > 0 and self.cfg.floor_weight > 0.0

    def pieces(self, times: np.ndarray | None, n: int) -> list[np.ndarray]:
        """Indices of the scan's points in each piece (``piece_s`` of when they were last
        seen), newest first; one piece without ``times`` or with ``piece_s`` 0."""
        span = self.cfg.piece_s
        if times is None or span <= 0 or n == 0:
            return [np.arange(n)]
        tt = np.asarray(times, dtype=np.float64)
        k = np.floor((float(tt.max()) - tt) / span).astype(np.int64)
        order = np.argsort(k, kind="stable")
        cuts = np.flatnonzero(np.diff(k[order])) + 1
        return np.split(order, cuts)

    def piece_scores(
        self, poses: np.ndarray, pts: np.ndarray, origins: np.ndarray | None, pieces: list[np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each pose's mean cost and fraction of points seen through walls (NaN without
        ``origins``) over the scan's ``pieces``, each piece refined on its own from the
        pose and kept within ``piece_shift_m`` and ``piece_turn_deg`` of it."""
        cfg = self.cfg
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        r2 = cfg.fine_robust_m**2
        n = len(pts)
        cost = np.zeros(len(poses))
        through = np.zeros(len(poses))
        shift2, turn = cfg.piece_shift_m**2, math.radians(cfg.piece_turn_deg)
        for idx in pieces:
            sub = np.ascontiguousarray(pts[idx])
            at = np.empty_like(poses)
            for i, p0 in enumerate(poses):
                p, c = _refine(self.dist, self.origin[0], self.origin[1], self.inv_cell, p0.copy(), sub, r2, 0.05, math.radians(1.0), 2)
                if (p[0] - p0[0]) ** 2 + (p[1] - p0[1]) ** 2 > shift2 or abs(wrap_angle(float(p[2] - p0[2]))) > turn:
                    p, c = p0, self.cost(p0, sub)
                at[i] = p
                cost[i] += c * len(idx)
            if origins is not None:
                through += self.scan_through_at(at, np.asarray(origins, dtype=np.float64)[idx], sub) * len(idx)
        if origins is None:
            through[:] = math.nan
        return cost / max(n, 1), through / max(n, 1)

    def rescore(
        self, poses: np.ndarray, pts: np.ndarray, frame_pts: np.ndarray | None = None, scene_lines=None,
        origins: np.ndarray | None = None, times: np.ndarray | None = None, floor: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> SearchResult:
        """Refine each hypothesis (robot poses in the map) on the scan ``pts`` (robot
        frame), score it on the scan's pieces (:meth:`piece_scores`, by ``times``, when
        each point was seen) with their sight through walls (from ``origins``, where each
        point was seen) and the sight lines to the ``floor`` points that cross walls,
        merge those that meet, check the latest frame's points ``frame_pts`` for sight
        through walls with ``scene_lines(x, y)``, and decide (module docstring)."""
        cfg = self.cfg
        pts = np.ascontiguousarray(pts, dtype=np.float64).reshape(-1, 2)
        r2 = cfg.fine_robust_m**2
        refined, rc = [], []
        for p0 in np.asarray(poses, dtype=np.float64).reshape(-1, 3):
            p, c = _refine(
                self.dist, self.origin[0], self.origin[1], self.inv_cell, p0.copy(), pts, r2,
                0.5 * cfg.grid_step_m, 0.5 * math.radians(cfg.heading_step_deg), 5,
            )
            p[2] = wrap_angle(float(p[2]))
            refined.append(p)
            rc.append(c)
        if not refined:
            return SearchResult((), None, "no hypothesis", 0)
        refined_a = np.array(refined)
        pieces = self.pieces(times, len(pts))
        if len(pieces) > 1:
            rc_a, st_a = self.piece_scores(refined_a, pts, origins, pieces)
            rc, st = list(rc_a), list(st_a)
        else:
            # All hypotheses' sight through walls in one kernel call (shared over the cores).
            st = [math.nan] * len(refined) if origins is None else list(self.scan_through_at(refined_a, origins, pts))
        ft = np.full(len(refined), math.nan)
        if self._uses_floor(floor):
            assert floor is not None
            ft = self.scan_through_at(refined_a, floor[1], floor[0], end_m=cfg.floor_jamb_m)
        score = np.array([c if math.isnan(t) else c + cfg.through_weight * t for c, t in zip(rc, st, strict=True)])
        score = score + cfg.floor_weight * np.nan_to_num(ft)
        order = np.argsort(score, kind="stable")
        modes = []
        for i in self._distinct(refined_a, order, cfg.modes):
            through = math.nan
            if frame_pts is not None and scene_lines is not None and len(frame_pts):
                at, rel = sensor_view(refined_a[i], frame_pts, self.sensor_xy)
                lines = np.ascontiguousarray(scene_lines(float(at[0]), float(at[1])), dtype=np.float64).reshape(-1, 4)
                v = explain_points(lines, at, rel, cfg.explain_m, cfg.through_m)
                through = float(np.count_nonzero(v < 0)) / len(v)
            modes.append(Mode(refined_a[i].copy(), float(rc[i]), through, float(st[i]), float(score[i]), float(ft[i])))
        return SearchResult(tuple(modes), *self._decide(modes, len(pts)), hypotheses=len(refined))

    def keeps_prior(self, prior: Mode, modes: tuple[Mode, ...] | list[Mode], n_points: int) -> bool:
        """A false alarm: does the belief before the alarm (``prior``, re-scored on the
        scan) still explain the scan? Yes when it scores at most ``prior_cost`` and within
        ``accept_margin`` of the best of ``modes``, or at most ``prior_lead_cost`` and
        better than every mode elsewhere by the acceptance margins."""
        cfg = self.cfg
        sep = math.radians(cfg.mode_separation_deg)
        elsewhere = [
            m.score for m in modes
            if math.hypot(m.pose[0] - prior.pose[0], m.pose[1] - prior.pose[1]) >= cfg.mode_separation_m
            or abs(wrap_angle(float(m.pose[2] - prior.pose[2]))) >= sep
        ]
        if prior.score <= cfg.prior_cost:
            return not modes or prior.score <= min(m.score for m in modes) + cfg.accept_margin
        if prior.score > cfg.prior_lead_cost:
            return False
        gap = (min(elsewhere) - prior.score) if elsewhere else math.inf
        return gap >= cfg.accept_margin and gap * n_points >= cfg.accept_margin_points

    def lead_allowed(self, mode: Mode, prior: Mode | None) -> bool:
        """May ``mode``, accepted by the decision, be taken while ``prior`` (the belief
        before the alarm, re-scored on the scan) stands? A mode scoring over
        ``accept_cost``, accepted on its lead alone, is not taken while the prior still
        scores within ``prior_lead_cost``: a hall's clutter can fit an office elsewhere
        better than the hall, whereas a robot carried away leaves a prior that scores
        worse than that (1.0 or more on the kidnappings measured)."""
        return mode.score <= self.cfg.accept_cost or prior is None or prior.score > self.cfg.prior_lead_cost

    def _decide(self, modes: list[Mode], n_points: int) -> tuple[Mode | None, str]:
        cfg = self.cfg
        if not modes:
            return None, "no mode"
        best = modes[0]
        gap = modes[1].score - best.score if len(modes) > 1 else math.inf
        if best.score > max(cfg.accept_cost, cfg.accept_lead_cost):
            return None, f"best mode explains too little (score {best.score:.2f} > {max(cfg.accept_cost, cfg.accept_lead_cost)})"
        if best.score > cfg.accept_cost and gap < cfg.accept_lead:
            return None, (
                f"best mode explains too little (score {best.score:.2f} > {cfg.accept_cost}) "
                f"and leads by {gap:.3f} < {cfg.accept_lead}"
            )
        if not math.isnan(best.through) and best.through > cfg.max_through:
            return None, f"best mode sees through walls ({best.through:.2f} of the frame)"
        if len(modes) > 1:
            if gap < cfg.accept_margin or gap * n_points < cfg.accept_margin_points:
                return None, f"ambiguous: {len(modes)} modes, the second within {gap:.3f} ({gap * n_points:.1f} points)"
        return best, f"score {best.score:.3f}, next {modes[1].score:.3f}" if len(modes) > 1 else f"score {best.score:.3f}"
