"""Localization health from the robot's own data: is the belief still explaining what it sees?

Nothing here reads the truth. Each frame the down-projected plane points (the CGR
observation) are checked against the map at the pose estimate, ray by ray
(:func:`explain_points`):

- a point within ``explain_m`` of the first mapped wall along its ray is **explained**;
- a point more than ``through_m`` *beyond* that wall **contradicts** the pose: people
  and furniture the map does not hold can only make the camera see less far than the
  map says, never farther, so a robot that sees through mapped walls is somewhere else;
- anything else (shorter than the wall: clutter) is neutral.

From these per-frame fractions the monitor keeps short- and long-term averages, as
augmented MCL does with the observation likelihood (Thrun, Burgard and Fox,
"Probabilistic Robotics", Table 8.3: ``w_fast`` and ``w_slow``): a drop of the short-term
explained fraction far below the long-term one means the world stopped matching the
belief, while a low long-term level (an atrium with few walls in view) is normal there
and raises no alarm. The monitor says **lost** when, for ``hold_s`` (``ratio_hold_s`` for the second test;
for the first two, counting only the frames with evidence), either

1. the short-term contradiction fraction is above ``lost_through``, or
2. the short-term explained fraction is below ``lost_ratio`` times the long-term one
   (with enough frames behind the long-term average), or
3. the particle spread is above ``lost_spread_m``,

or at once when

4. the localizer moved the belief more than ``jump_m`` beyond what the odometry says
   within ``jump_s`` while the short-term explained fraction was below ``jump_ratio``
   times the long-term one: the belief had stopped explaining the view and then jumped
   to fit it. CGR's corrections on a tracked belief stay far smaller, so the belief
   before the jump was wrong, and a belief that wrong may have settled on the wrong one
   of two places the map repeats (a robot carried along a corridor). Without
   ``min_history_s`` behind the long-term average (just after a relocalization, which
   resets it) the jump alone says lost: CGR restarted around an accepted pose corrects
   it by a restart spread or two, and a jump of ``jump_m`` moves the belief off the
   place the search chose to one that fits a few frames better (unmapped furniture
   filling the view at the accepted, right, place), or
5. the camera's view disagreed with the odometry's prediction of it from the last
   frame (:mod:`autonomy.localization.view_check`: agreement below ``view_agree``) on
   ``view_frames`` frames in a row: the robot was carried or pushed, and its belief
   went nowhere;

or, for ``hold_s`` of frames with evidence, when

6. the short-term fraction of the pixels expecting a mapped wall within the camera's
   range that saw past it (:mod:`autonomy.localization.missing_walls`: mostly the floor beyond where
   the wall should stand) is above ``lost_missing``: the walls the belief puts in view
   are not there, which in an open hall, where the camera sees nothing but floor, is the
   only evidence there is;

and **blind** when no usable frame has arrived for ``blind_s`` (a
camera blackout, dropped or corrupted frames: the estimate is dead reckoning then).
The thresholds were chosen on tuning seeds; docs/localization.md gives the method and
docs/results.md its false alarms and misses against the truth on other seeds.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numba
import numpy as np

from autonomy.common.errors import require_int, require_non_negative, require_positive
from autonomy.maps.raycast import ray_hit_nb

#: Health states, in the order of severity.
STATES = ("ok", "blind", "lost")

#: The lost tests on the short-term averages of the map's verdicts: their hold counts
#: only the time of frames with evidence.
MAP_TESTS = ("sees through walls", "explains little")

#: The lost test on the short-term missing-wall fraction, held on its own evidence.
MISSING_TEST = "walls missing"


@dataclass(frozen=True)
class HealthConfig:
    """Thresholds of the lost and blind tests (chosen on tuning seeds)."""

    explain_m: float = 0.15
    """A point within this of the first mapped wall along its ray is explained."""
    through_m: float = 0.4
    """A point this far beyond the first mapped wall along its ray contradicts the pose."""
    min_points: int = 30
    """Frames with fewer observation points carry no evidence."""
    fast_s: float = 1.0
    """Time constant of the short-term averages."""
    slow_s: float = 30.0
    """Time constant of the long-term explained average."""
    lost_through: float = 0.3
    """Lost when the short-term contradiction fraction is above this ..."""
    lost_ratio: float = 0.2
    """... or the short-term explained fraction is below this fraction of the long-term one ..."""
    lost_spread_m: float = 1.0
    """... or the particles' position spread is above this ..."""
    hold_s: float = 1.5
    """... for this long (the ratio test for ``ratio_hold_s``: a robot turning from a
    corridor to face an open hall's furniture sees little of the map for a few seconds).
    The two tests on the map's verdicts count only the time of frames with evidence
    (``min_points``): in an open hall a few frames of furniture and then seconds of
    nothing in range held the short-term average low, and said lost on those frames."""
    ratio_hold_s: float = 4.0
    min_history_s: float = 5.0
    """The ratio test needs this much observed time behind the long-term average."""
    jump_m: float = 0.5
    """Lost at once when the localizer moves the belief this far beyond the odometry ..."""
    jump_s: float = 1.0
    """... within this long (net, so frame-to-frame jitter cancels) ..."""
    jump_ratio: float = 0.5
    """... while the short-term explained fraction was below this fraction of the
    long-term one in that time, or there was not ``min_history_s`` behind the long-term
    one yet (0 turns the test off)."""
    view_agree: float = 0.3
    """Lost at once when the view agreed with the odometry's prediction of it
    (:mod:`autonomy.localization.view_check`) less than this ... (0 turns the test off)"""
    view_frames: int = 1
    """... on this many frames with evidence in a row (a robot put down elsewhere gives
    one such frame when the view check compares consecutive frames, ``lag_s`` 0)."""
    lost_missing: float = 0.4
    """Lost when the short-term fraction of the pixels expecting a mapped wall that saw
    past it (:mod:`autonomy.localization.missing_walls`) is above this for ``hold_s`` of frames with
    that evidence (0 turns the test off)."""
    blind_s: float = 0.5
    """Blind when no usable frame has arrived for this long."""

    def __post_init__(self) -> None:
        require_positive(self, "recovery.health.", "explain_m", "through_m", "fast_s", "slow_s", "lost_spread_m", "blind_s", "jump_m", "jump_s")
        require_non_negative(self, "recovery.health.", "lost_through", "lost_ratio", "hold_s", "ratio_hold_s", "min_history_s", "jump_ratio", "view_agree", "lost_missing")
        require_int(self, "recovery.health.", "min_points", minimum=1)
        require_int(self, "recovery.health.", "view_frames", minimum=1)


@numba.njit(cache=True)
def explain_points(lines, pose, pts, explain_m, through_m):  # pragma: no cover - numba
    """Per point (in the frame of ``pose``) at ``pose``: 1 explained, -1 contradicts (seen
    through a wall), 0 neither, against the first of ``lines`` (world frame) hit by its
    ray from ``pose``'s position (:func:`autonomy.maps.raycast.ray_hit`'s kernel). Give the
    camera's pose and the points relative to it (:func:`autonomy.common.geometry.sensor_view`):
    the rays start there. Points whose ray hits no line are neither."""
    x, y, th = pose[0], pose[1], pose[2]
    c, s = math.cos(th), math.sin(th)
    n = pts.shape[0]
    out = np.zeros(n, np.int8)
    for i in range(n):
        qx = c * pts[i, 0] - s * pts[i, 1]
        qy = s * pts[i, 0] + c * pts[i, 1]
        r = math.sqrt(qx * qx + qy * qy)
        if r <= 0.0:
            continue
        bj, best_t = ray_hit_nb(lines, x, y, qx / r, qy / r)
        if bj < 0:
            continue
        if r > best_t + through_m:
            out[i] = -1
            continue
        # Distance of the point from the (extended) line it is associated with.
        ax, ay = lines[bj, 0], lines[bj, 1]
        ex, ey = lines[bj, 2] - ax, lines[bj, 3] - ay
        L = math.sqrt(ex * ex + ey * ey)
        if L <= 0.0:
            continue
        d = abs((x + qx - ax) * ey - (y + qy - ay) * ex) / L
        if d <= explain_m:
            out[i] = 1
    return out


@dataclass(frozen=True)
class HealthSample:
    """One frame of the health signal (for reports and viewers)."""

    t: float
    state: str
    """ok, blind or lost."""
    explained: float
    """This frame's explained fraction (NaN: no evidence this frame)."""
    through: float
    """This frame's contradiction fraction (NaN: no evidence)."""
    explained_fast: float
    explained_slow: float
    through_fast: float
    spread_m: float
    reason: str
    """Which test said lost or blind ('' when ok)."""
    jump_m: float = 0.0
    """How far the localizer moved the belief beyond the odometry within ``jump_s`` (net)."""
    view_agree: float = math.nan
    """This frame's agreement of the view with the odometry (NaN: no evidence)."""
    missing: float = math.nan
    """This frame's fraction of the pixels expecting a mapped wall that saw past it (NaN:
    no evidence)."""
    missing_fast: float = math.nan
    """Its short-term average."""


class HealthMonitor:
    """Short- and long-term averages of the explained and contradiction fractions, and
    the lost / blind decision (module docstring)."""

    def __init__(self, cfg: HealthConfig = HealthConfig()) -> None:
        self.cfg = cfg
        self.reset(0.0)

    def reset(self, t: float, keep_long_term: bool = False) -> None:
        """Forget the short-term evidence (after a relocalization); the long-term level
        of the place is kept when asked (the robot is where it was believed to be)."""
        self.e_fast = math.nan
        self.th_fast = math.nan
        self.m_fast = math.nan
        self._m_t = math.nan
        if not keep_long_term:
            self.e_slow = math.nan
            self.history_s = 0.0
        self.last_t = math.nan
        self._moves: deque[tuple[float, float, float, float]] = deque()
        self._move_x = self._move_y = 0.0
        self.jump_m = 0.0
        self.view_low = 0
        """Frames with evidence in a row whose view disagreed with the odometry."""
        self.last_evidence_t = t
        self.bad_since = math.nan
        self.bad_evidence_s = 0.0
        """Time on frames with evidence since a map test began to hold."""
        self.state = "ok"
        self.reason = ""
        self.last = HealthSample(t, "ok", math.nan, math.nan, math.nan, math.nan, math.nan, 0.0, "")

    def update(
        self,
        t: float,
        verdicts: np.ndarray | None,
        spread_m: float,
        correction: tuple[float, float] | None = None,
        view_agree: float = math.nan,
        missing: float = math.nan,
    ) -> HealthSample:
        """Fold in one frame's per-point verdicts (:func:`explain_points`; None: no usable
        frame; fewer than ``min_points``: a frame, but no evidence), the belief's spread,
        the localizer's ``correction`` this frame (world x, y: the belief after the update
        minus the odometry's prediction of it; None: none) and the view's agreement with
        the odometry (:class:`autonomy.localization.view_check.ViewCheck`; NaN: no evidence) and the
        fraction of the pixels expecting a mapped wall that saw past it
        (:func:`autonomy.localization.missing_walls.missing_walls`; NaN: no evidence); returns the
        frame's :class:`HealthSample`."""
        cfg = self.cfg
        dt = 0.0 if math.isnan(self.last_t) else max(0.0, t - self.last_t)
        self.last_t = t
        e = th = math.nan
        if verdicts is not None:
            self.last_evidence_t = t  # a usable frame, even if it shows little
        if verdicts is not None and len(verdicts) >= cfg.min_points:
            n = len(verdicts)
            e = float(np.count_nonzero(verdicts > 0)) / n
            th = float(np.count_nonzero(verdicts < 0)) / n
        if math.isfinite(view_agree):
            self.view_low = self.view_low + 1 if view_agree < cfg.view_agree else 0
        if not math.isnan(e):
            a_fast = 1.0 - math.exp(-dt / cfg.fast_s)
            a_slow = 1.0 - math.exp(-dt / cfg.slow_s)
            self.e_fast = e if math.isnan(self.e_fast) else self.e_fast + a_fast * (e - self.e_fast)
            self.th_fast = th if math.isnan(self.th_fast) else self.th_fast + a_fast * (th - self.th_fast)
            self.e_slow = e if math.isnan(self.e_slow) else self.e_slow + a_slow * (e - self.e_slow)
            self.history_s += dt
        m = float(missing)
        if math.isfinite(m):
            a = 1.0 if math.isnan(self._m_t) else 1.0 - math.exp(-max(0.0, t - self._m_t) / cfg.fast_s)
            self.m_fast = m if math.isnan(self.m_fast) else self.m_fast + a * (m - self.m_fast)
            self._m_t = t
        self._track_moves(t, correction)
        reason = self._lost_reason(spread_m)
        if reason:
            if math.isnan(self.bad_since):
                self.bad_since = t
                self.bad_evidence_s = 0.0
            elif math.isfinite(m) if reason == MISSING_TEST else not math.isnan(e):
                self.bad_evidence_s += dt
            hold = {"explains little": cfg.ratio_hold_s, "belief jumped": 0.0, "view jumped": 0.0}.get(reason, cfg.hold_s)
            # The map tests' short-term averages move only on frames with evidence; held
            # on without any (the camera facing open space past its range, or blocked),
            # they would say lost on a few frames seen seconds ago.
            held = self.bad_evidence_s if (reason in MAP_TESTS or reason == MISSING_TEST) else t - self.bad_since
            state = "lost" if held >= hold else ("blind" if t - self.last_evidence_t > cfg.blind_s else "ok")
        else:
            self.bad_since = math.nan
            self.bad_evidence_s = 0.0
            state = "blind" if t - self.last_evidence_t > cfg.blind_s else "ok"
            reason = "no frames" if state == "blind" else ""
        self.state, self.reason = state, reason if state != "ok" else ""
        self.last = HealthSample(t, state, e, th, self.e_fast, self.e_slow, self.th_fast, float(spread_m), self.reason, self.jump_m, float(view_agree), m, self.m_fast)
        return self.last

    def _ratio(self) -> float:
        """Short- over long-term explained fraction (NaN without enough history)."""
        if math.isnan(self.e_fast) or self.history_s < self.cfg.min_history_s or not self.e_slow > 0.0:
            return math.nan
        return self.e_fast / self.e_slow

    def _track_moves(self, t: float, correction: tuple[float, float] | None) -> None:
        """The net correction over the last ``jump_s`` (running sums over a window)."""
        if correction is not None and math.isfinite(correction[0]) and math.isfinite(correction[1]):
            cx, cy = float(correction[0]), float(correction[1])
            # No long-term level yet (a relocalization reset it): the jump alone counts.
            r = -math.inf if self.history_s < self.cfg.min_history_s else self._ratio()
            self._moves.append((t, cx, cy, r))
            self._move_x += cx
            self._move_y += cy
        while self._moves and self._moves[0][0] <= t - self.cfg.jump_s:
            _, cx, cy, _ = self._moves.popleft()
            self._move_x -= cx
            self._move_y -= cy
        if not self._moves:
            self._move_x = self._move_y = 0.0
        self.jump_m = math.hypot(self._move_x, self._move_y)

    def _jumped(self) -> bool:
        cfg = self.cfg
        if cfg.jump_ratio <= 0.0 or self.jump_m <= cfg.jump_m:
            return False
        return any(r < cfg.jump_ratio for _, _, _, r in self._moves)

    def _lost_reason(self, spread_m: float) -> str:
        cfg = self.cfg
        if spread_m > cfg.lost_spread_m:
            return "spread"
        if not math.isnan(self.th_fast) and self.th_fast > cfg.lost_through:
            return "sees through walls"
        if self._jumped():
            return "belief jumped"
        if self.view_low >= cfg.view_frames:
            return "view jumped"
        # After the tests that say lost at once: held first, this one would keep them
        # waiting for its hold.
        if cfg.lost_missing > 0.0 and not math.isnan(self.m_fast) and self.m_fast > cfg.lost_missing:
            return MISSING_TEST
        if (
            not math.isnan(self.e_fast)
            and self.history_s >= cfg.min_history_s
            and self.e_fast < cfg.lost_ratio * self.e_slow
        ):
            return "explains little"
        return ""
