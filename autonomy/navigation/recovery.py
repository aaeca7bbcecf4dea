"""Progress watch, back-off and look-back: what the navigator does when it makes no way.

No progress for ``stuck_time_s`` starts a recovery (the navigator re-plans; then this
backs off along the trail, or turns towards the new plan, or looks back); what blocks
the way too close for the camera to see starts a back-off until the camera can look at
it again. The camera never looks behind the robot, so a back-off goes only along the
robot's own trail (:mod:`autonomy.navigation.trail`); a stuck robot that may not back off
and whose plan still leads the blocked way turns round and drives away seeing
(``look_back_m``).
"""

from __future__ import annotations

import math

import numpy as np

from autonomy.common.geometry import wrap_angle
from autonomy.navigation.avoidance import AvoidanceConfig, AvoidanceResult
from autonomy.navigation.config import NavCommand, NavigatorConfig
from autonomy.navigation.plan import Plan
from autonomy.navigation.steering import Steering, turn_rate
from autonomy.navigation.surroundings import Surroundings
from autonomy.navigation.trail import Trail
from autonomy.perception.camera import DepthCamera

_LOOK_BACK_FACING_RAD = math.radians(10.0)
"""A look back drives once the robot faces the way back this closely."""


class Recovery:
    """The stuck clock, the back-off under way and the look back under way.

    ``surroundings`` (the map's walls and the memory), ``trail`` and ``steering`` are the
    navigator's: a back-off checks its way back against the first and retraces the
    second; a look back chooses its direction with the third.
    """

    def __init__(
        self,
        cfg: NavigatorConfig,
        avoid: AvoidanceConfig,
        camera: DepthCamera,
        surroundings: Surroundings,
        trail: Trail,
        steering: Steering,
    ) -> None:
        self.cfg = cfg
        self.avoid = avoid
        self.camera = camera
        self.surroundings = surroundings
        self.trail = trail
        self.steering = steering
        self.recoveries = 0
        """Recoveries started (``stuck_time_s``)."""
        self._best_s = 0.0
        self._progress_t = 0.0
        self._backoff_until = -1.0
        self._backoff_started = -np.inf
        self._stuck_backoff = False
        """The back-off under way is a recovery's (else a blind block's)."""
        self._look_back: tuple[float, np.ndarray | None, float] | None = None
        """A look back under way (``look_back_m``): the heading to face, where the drive
        that way began (None while turning) and when it ends at the latest."""

    # -- the stuck clock ----------------------------------------------------------------
    @property
    def progress_t(self) -> float:
        """When the robot last made progress (the stuck clock's start)."""
        return self._progress_t

    def restart(self, t: float) -> None:
        """A new plan: progress is measured along it from its start, from ``t``."""
        self._best_s = 0.0
        self._progress_t = t

    def hold(self, t: float) -> None:
        """Start the stuck clock again at ``t`` (the robot is busy elsewhere)."""
        self._progress_t = t

    def stuck(self, s: float, t: float) -> bool:
        """Record progress along the plan (arc length ``s``); True when there has been
        none for ``stuck_time_s``."""
        cfg = self.cfg
        if s > self._best_s + cfg.stuck_progress_m:
            self._best_s = s
            self._progress_t = t
            return False
        return t - self._progress_t > cfg.stuck_time_s

    def stop(self) -> None:
        """End a back-off or a look back under way."""
        self._backoff_until = -1.0
        self._backoff_started = -np.inf
        self._look_back = None

    def forget(self) -> None:
        """:meth:`stop`, and forget whose the back-off was (the pose estimate jumped)."""
        self.stop()
        self._stuck_backoff = False

    # -- the back-off -------------------------------------------------------------------
    @property
    def stuck_backoff(self) -> bool:
        """The back-off under way is a recovery's, not a blind block's."""
        return self._stuck_backoff

    def backing_off(self, obstacles: np.ndarray, t: float) -> bool:
        """Whether a back-off goes on at ``t``: at least ``backoff_time_s``, and on until
        what blocked the way is in the camera's view again (or ``max_backoff_s`` has passed)."""
        return t < self._backoff_until or (
            t - self._backoff_started < self.cfg.max_backoff_s and self.surroundings.blind_blocked(obstacles)
        )

    def end_backoff(self) -> None:
        self._backoff_until = -1.0
        self._backoff_started = -np.inf

    def _start_backoff(self, t: float, stuck: bool) -> None:
        self._backoff_until = t + self.cfg.backoff_time_s
        self._backoff_started = t
        self._stuck_backoff = stuck

    def back_off(self, plan: Plan, pose: np.ndarray, obstacles: np.ndarray, t: float) -> NavCommand | None:
        """The back-off's command while it goes on (:meth:`backing_off`); None once it is over.

        Back off unless there is no way back. After a stuck recovery's back-off the stuck
        clock starts again (run on through a long back-off, it would send the robot from
        one recovery straight into the next, for ever, where it cannot back off); a
        back-off from a blind block counts as no progress. Where it may not back off
        (:meth:`backoff_velocity`), the robot turns in place towards its plan until
        ``backoff_time_s`` is over."""
        v = self.backoff_velocity(pose, obstacles, t)
        if self._stuck_backoff:
            self._progress_t = t
        if v.any():
            return NavCommand(v, "recovering")
        if t < self._backoff_until:
            return NavCommand(np.array([0.0, 0.0, self.steering.toward_plan(plan, pose)[2]]), "recovering")
        self._backoff_started = -np.inf
        return None

    def start(self, plan: Plan, pose: np.ndarray, obstacles: np.ndarray, t: float) -> NavCommand:
        """A recovery, once the navigator has re-planned (``plan``): back off; where the
        robot may not (:meth:`backoff_velocity`), turn in place towards the plan, or, when
        that still leads ahead, look back (``look_back_m``, :meth:`look_back`)."""
        cfg = self.cfg
        self.recoveries += 1
        self._start_backoff(t, True)
        v = self.backoff_velocity(pose, obstacles, t)
        if v.any():
            return NavCommand(v, "recovering")
        _, desired, omega = self.steering.toward_plan(plan, pose)
        if cfg.look_back_m > 0 and abs(desired) <= cfg.turn_in_place_rad:
            turn_s = math.pi / cfg.max_turn_rate_rad_s
            drive_s = cfg.look_back_m / max(cfg.backoff_speed_mps, 1e-9)
            self._look_back = (wrap_angle(float(pose[2]) + math.pi), None, t + 2.0 * turn_s + drive_s)
            return self.look_back(pose, obstacles, t) or NavCommand(np.array([0.0, 0.0, omega]), "recovering")
        return NavCommand(np.array([0.0, 0.0, omega]), "recovering")

    def when_blocked(
        self, pose: np.ndarray, obstacles: np.ndarray, t: float, carrot: np.ndarray, desired: float, turn: float, res: AvoidanceResult
    ) -> NavCommand:
        """No direction is open (and no re-plan goes round it): back off if what blocks is
        too close for the camera to see, else wait turning towards the carrot (``turn``)."""
        fan = (res.angles, res.lengths)
        back = self.backoff_velocity(pose, obstacles, t) if self.surroundings.blind_blocked(obstacles) else np.zeros(3)
        if back.any():
            # What blocks is too close for the camera to see: back off until it can
            # look again (a person may have moved on; else it is seen and avoided).
            self._start_backoff(t, False)
            return NavCommand(back, "recovering", carrot, desired, res.theta_star, res.open_length_m, fan)
        # Wait (turning towards the carrot): people step aside; stuck detection recovers.
        return NavCommand(np.array([0.0, 0.0, turn]), "blocked", carrot, desired, res.theta_star, res.open_length_m, fan)

    def backoff_velocity(self, pose: np.ndarray, obstacles: np.ndarray, t: float) -> np.ndarray:
        """Recovery motion: back off the way the robot came, where nothing is in the way.

        Behind the robot the camera sees nothing, so with the trail on (``trail_s``) the
        robot only retraces its own trail (:meth:`Trail.retrace` as of ``t``): the space
        its body has just swept is the only evidence there is that the way back is free.
        A straight line near the trail is not enough: a robot that passed a person at a
        door jamb with millimetres to spare, whom the jamb had hidden from the camera,
        touches them backing off straight 5 cm beside the way it came. The way back is
        taken when its first stretch runs within 75 degrees of straight back and the
        map's walls and the remembered obstacles keep ``backoff_clearance_m`` from it
        (someone may have stepped in since); else no translation (the robot re-plans
        where it stands). With the trail off: straight back if that holds for
        ``backoff_check_m``, else the nearest such direction within 75 degrees of it
        (the map and memory only).
        """
        cfg = self.cfg
        pts = np.asarray(obstacles, dtype=np.float64).reshape(-1, 2)
        walls = self.surroundings.map_points(pose, cfg.backoff_check_m + self.avoid.robot_radius_m + 0.2)
        pts = np.vstack([pts, walls, self.surroundings.remembered])
        clear = self.avoid.robot_radius_m + cfg.backoff_clearance_m
        if cfg.trail_s > 0:
            return self.trail.retrace_velocity(pose, pts, clear, t)
        for k in (0, 1, -1, 2, -2, 3, -3, 4, -4, 5, -5):
            phi = math.pi + k * math.radians(15.0)
            u = np.array([math.cos(phi), math.sin(phi)])
            ahead = pts[pts @ u > 0.0] if len(pts) else pts  # what lies the other way never blocks
            if len(ahead):
                along = np.clip(ahead @ u, 0.0, cfg.backoff_check_m)
                if float(np.min(np.hypot(ahead[:, 0] - along * u[0], ahead[:, 1] - along * u[1]))) < clear:
                    continue
            return np.array([cfg.backoff_speed_mps * u[0], cfg.backoff_speed_mps * u[1], 0.0])
        return np.zeros(3)

    # -- the look back ------------------------------------------------------------------
    @property
    def looking_back(self) -> bool:
        return self._look_back is not None

    def look_back(self, pose: np.ndarray, obstacles: np.ndarray, t: float) -> NavCommand | None:
        """The look back's command (``look_back_m``); None once it is over. Turn in place
        to face the way back; then drive that way as forward driving does -- Eq. 5 on what
        the camera, the memory and the near field show, in the camera's view only, at
        ``backoff_speed_mps`` at most -- until ``look_back_m`` is behind, the way is
        blocked or the time is up. The stuck clock starts again after it."""
        cfg = self.cfg
        assert self._look_back is not None
        heading, start, until = self._look_back
        self._progress_t = t
        xy = np.asarray(pose[:2], dtype=np.float64)
        err = wrap_angle(heading - float(pose[2]))
        if t > until or (start is not None and math.hypot(xy[0] - start[0], xy[1] - start[1]) >= cfg.look_back_m):
            self._look_back = None
            return None
        if start is None:
            if abs(err) > _LOOK_BACK_FACING_RAD:
                return NavCommand(np.array([0.0, 0.0, turn_rate(cfg, err)]), "recovering")
            self._look_back = (heading, xy.copy(), until)
        res = self.steering.choose_direction(pose, obstacles, err)
        if res.blocked:
            self._look_back = None
            return None
        th = res.theta_star
        omega = turn_rate(cfg, th)
        fan = (res.angles, res.lengths)
        if abs(th) > 0.5 * self.camera.fov_h_rad:
            return NavCommand(np.array([0.0, 0.0, omega]), "recovering", theta_star_rad=th, open_length_m=res.open_length_m, fan=fan)
        speed = min(cfg.backoff_speed_mps, res.safe_speed_mps)
        v = np.array([speed * math.cos(th), speed * math.sin(th), omega])
        return NavCommand(v, "recovering", theta_star_rad=th, open_length_m=res.open_length_m, fan=fan)
