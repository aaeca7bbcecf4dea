"""The navigator's parameters (the scenario keys ``navigator.<field>``) and its command.

:class:`NavigatorConfig` is flat on purpose: each field is a user-facing key, whichever
part of the navigator (:mod:`autonomy.navigation.navigator`) reads it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from autonomy.common.errors import InputError, require_non_negative, require_positive

MEMORY_KEEP_MARGIN_M = 0.5
"""Remembered points are dropped beyond memory_radius_m plus this (the robot moves on)."""


@dataclass(frozen=True)
class NavigatorConfig:
    """Carrot following, speed and recovery parameters."""

    cruise_speed_mps: float = 0.75
    """Speed on open paths (CoBot: 0.75 m/s)."""
    lookahead_m: float = 0.8
    """Carrot distance ahead along the plan."""
    narrow_lookahead_m: float = 0.3
    """Carrot distance on and before narrow edges (ours, as nav2's regulated pure pursuit
    shortens its lookahead where it must track closely; 0 = off, ``lookahead_m``
    everywhere): carrot following cuts a plan's corner by about a third of its lookahead
    and closes the offset over a few lookaheads. With the long carrot a robot turning off
    a corridor 1 m before a 0.91 m door enters it about 0.16 m off its centre, where a
    centred robot has 0.15 m to spare on each side; the short carrot lines it up first."""
    narrow_horizon_m: float = 1.0
    """While the carrot is short, Eq. 5 scores open lengths only up to this (ours; 0 =
    uncapped): leaving a door towards a corridor's wall 1.8 m ahead, the corridor's two
    ways, open 4 m at 35 degrees off the carrot, would out-score the carrot's direction,
    and the robot would turn to one and the other in turn rather than drive out."""
    narrow_slack_m: float = 0.25
    """An edge is narrow when it passes a door (``has_door``) or its ``max_clearance``
    leaves less than this beside the robot's radius ..."""
    narrow_before_m: float = 2.75
    """... and the short carrot holds from this far before the narrow stretch of such an
    edge (where the map's walls come within that distance of it; the whole edge without
    walls) until the robot's back has left the stretch: a door's node 1.075 m off the
    corridor's centre line has its stretch from 0.31 m before the door, so the corner
    before it is taken tightly too, and the carrot is long again 0.3 m past the jambs
    rather than 1 m on at the corridor's centre, where a short carrot pointing at the
    far wall would leave the robot turning to and fro between the corridor's two ways."""
    arrival_radius_m: float = 0.35
    """The goal counts as reached within this distance."""
    heading_gain: float = 2.0
    """Yaw rate per radian of heading error."""
    max_turn_rate_rad_s: float = 1.5
    """Yaw-rate limit."""
    turn_in_place_rad: float = math.radians(45.0)
    """Turn in place while the carrot is more than this off the heading."""
    stuck_time_s: float = 6.0
    """No progress for this long triggers a recovery."""
    stuck_progress_m: float = 0.25
    """Progress (m along the plan) that counts within stuck_time_s."""
    backoff_time_s: float = 2.0
    """Recovery: back off for this long ..."""
    backoff_speed_mps: float = 0.15
    """... at this speed, then re-plan."""
    max_backoff_s: float = 8.0
    """Backing off goes on past backoff_time_s while an obstacle remembered in the path
    is still too close for the camera to see, up to this long."""
    backoff_memory_s: float = 30.0
    """Remembered obstacles count this long for the back-off's check of the way back,
    which the camera never sees (the avoidance forgets them after ``memory_s``): a robot
    backing off for a few seconds would otherwise drive into furniture it passed a while
    ago and has since forgotten."""
    backoff_check_m: float = 0.4
    """The way back is checked this far against map walls and remembered obstacles."""
    backoff_clearance_m: float = 0.08
    """... and must keep this clearance (beyond the robot radius) from them. The map's
    walls are placed through the pose estimate, and nothing behind the robot corrects
    it: the margin covers the localization's usual error (a few cm; an estimate 6 cm off
    across a door puts a robot backing 3 cm clear of the map's jamb onto the real one). A
    0.92 m door leaves 0.16 m beside the robot, so it backs through one within 8 cm of its
    centre; elsewhere it turns towards its plan or looks back, which the camera sees."""
    trail_s: float = 30.0
    """A back-off needs the evidence driving forward has, that the space is free: the
    camera never saw the way back, and no remembered obstacle there is no proof that
    nothing stands there (furniture the camera could not see). So the robot backs off
    only along its own trail, the footprints (pose estimates) of the last ``trail_s``:
    the whole back-off (``backoff_check_m``) must stay within ``trail_tolerance_m`` of
    them; else it turns in place towards its plan (turning is always safe for a round
    robot) and drives forward once it looks. 0 = off (back off wherever the map and the
    memory leave room)."""
    trail_tolerance_m: float = 0.1
    """... this far off the trail's footprints at most."""
    look_back_m: float = 1.0
    """A stuck robot that may not back off (``trail_s``) and whose re-plan still leads
    the way it is blocked (no other way, e.g. a person it meets in a doorway it has just
    turned round in) turns round in place to look the way back, drives this far that
    way as it drives forward (seen, Eq. 5, at ``backoff_speed_mps``), and then takes up
    its plan again; else the two would wait for each other. 0 = off: wait turning
    towards the plan."""
    blocked_edge_s: float = 120.0
    """A stuck robot (``stuck_time_s``), or one Eq. 5 finds blocked after
    ``blocked_wait_s`` without progress, marks the plan's navigation-graph edges that
    the blocking obstacle stands on (sensed points on the plan's line ahead, placed
    through the pose estimate, within the avoidance radius of the edge) as blocked and
    re-plans without them (a box or a closed door across a corridor is not in the map:
    re-planning the same way would lead back into it). A mark lasts this long (a person
    who stood there moves on); all are forgotten when no path is left without them.
    0 = off (re-plan on the whole graph)."""
    blocked_wait_s: float = 3.0
    """... blocked this long without progress (a person walking past blocks briefly) ..."""
    blocked_check_m: float = 1.5
    """... with the obstacle on the plan's line no farther ahead than this."""
    long_detour_m: float = 20.0
    """A re-plan round a block (either way above) that is longer than what is left of the
    plan by more than this ..."""
    long_detour_wait_s: float = 10.0
    """... is taken only once the block has held this long since such a re-plan was
    first put off (ours; 0 = at once): a person stepping out at a corridor's corner
    blocks it for a few seconds, and giving that corridor up for ``blocked_edge_s`` can
    mean 100 m round the building. Meanwhile the robot waits, backs off and tries the
    way again, as without marks."""
    look_turn_rate_rad_s: float = 0.6
    """Yaw rate of :meth:`Navigator.look_around` (turning in place so that the camera
    sweeps the walls, e.g. while the localization searches for the robot)."""
    exclude_stairs: bool = True
    """Plans avoid edges flagged has_stairs."""
    coastal_weight: float = 2.0
    """Coastal navigation (after Roy, Burgard, Fox and Thrun, ICRA 1999; ours): a metre of
    plan where the camera, facing along it, sees no wall within ``coastal_range_m`` costs
    1 + this many metres (:func:`autonomy.maps.planner.blind_lengths`), so plans keep walls
    in view where a detour allows it. The localization matches walls only: across a hall
    or down a wide corridor's middle it dead-reckons, and the belief that comes out of
    20 m of that (0.3-0.5 m wide on a real floor) can match the first far face it sees
    to a parallel wall behind it (0 = shortest paths)."""
    coastal_range_m: float = 3.5
    """Walls farther than this are not counted as seen for :attr:`coastal_weight` (FSPF
    keeps few points of a wall at the Kinect's 4 m)."""
    shortcut_clearance_m: float = 0.6
    """Any-angle plans (ours, as the smoothers of nav2 or Theta* straighten grid and graph
    paths): the plan goes straight from a vertex to the farthest later node of its run of
    plain edges (no door, no narrow stretch, no speed limit) when the straight line keeps
    this far from every wall and from what blocked an edge, and is blind
    (:attr:`coastal_weight`) for at most ``shortcut_blind_slack_m`` more than the nodes'
    way. Graphs made from the walls zigzag through halls (15-19 degrees of turning a
    metre on real floors), and with the camera seeing no wall every turn adds the
    odometry's rotation error to the heading the belief dead-reckons on (0 = the graph's
    own paths)."""
    shortcut_blind_slack_m: float = 0.5
    """See :attr:`shortcut_clearance_m`."""
    memory_s: float = 2.0
    """Obstacle memory: sensed points outside the camera's view persist this long (the
    Kinect sees +-29 degrees and nothing closer than 0.8 m, so a person beside or right
    in front of the robot is out of view exactly when it matters); 0 = react to the
    current frame only, as the paper."""
    unseen_speed_mps: float = 0.3
    """Speed limit while the chosen direction lies outside the camera's field of view: the
    open length there is known only from memory, so the robot looks (it turns towards the
    direction) before it drives fast (a person walking into the corridor it is turning
    into is unseen until then); 0 = off (as the paper). Only with ``look_first`` off."""
    look_first: bool = True
    """Translate only in directions the camera looks: while Eq. 5's direction lies outside
    its field of view, turn towards it in place (state "turning"), then drive (ours; the
    paper's robot drove wherever Eq. 5 pointed). A person standing beside the robot in a
    doorway it turns towards has never been in view; driving there, even slowly, runs
    into them, while turned first the camera (or the near field) sees them.
    Off: drive there at ``unseen_speed_mps``."""
    corner_speed_mps: float = 0.4
    """Speed limit round the plan's corners (blind corners): the camera cannot see into
    the corridor the robot turns into, nor beside itself, so it takes corners slowly
    enough to stop for a person it meets there, such as one turning the same corner just
    ahead of it (ours, as nav2's regulated pure pursuit slows for curvature). 0 = off
    (as the paper)."""
    edge_speed_limits: bool = True
    """Honour the navigation graph's per-edge ``max_speed`` (the map format's field; the
    shipped building's doors say 0.5 m/s) from ``lookahead_m`` before an edge until the
    robot's back has left it. A ``max_speed`` of 0 means no limit."""
    map_blind_spots_m: float = 0.7
    """Map walls within this distance of the robot and outside the camera's view join the
    obstacles (ours, like nav2's static costmap layer): the camera sees neither beside the
    robot nor closer than 0.8 m, and the memory forgets a wall after ``memory_s``, so a
    robot swerving round a person would scrape the corridor wall beside it. 0 = off."""
    map_clearance_m: float = 0.05
    """Map walls are kept this far beyond the robot radius (the avoidance's safety margin
    applies to sensed points; the map's walls are placed through the pose estimate, and
    doors leave 7 cm beside the margin)."""
    proximity_speed_mps: float = 0.4
    """At most this speed while a sensed or remembered obstacle lies within
    ``proximity_gap_m`` beyond the avoidance corridor of the chosen direction, less than
    ``proximity_range_m`` ahead (ours, like nav2's cost-regulated speed near obstacles):
    Eq. 3-5 treat a person walking towards the robot as standing still, so a person
    passed 0.4 m abeam at cruise speed is met as soon as they step, or the robot turns,
    into the other's way (e.g. a person crossing 1 m ahead while the robot swerves).
    0 = off (as the paper)."""
    proximity_gap_m: float = 0.3
    """... this far beyond the avoidance radius ..."""
    proximity_range_m: float = 1.5
    """... and closer than this ahead."""
    corner_angle_rad: float = math.radians(35.0)
    """A plan vertex turning by more than this is a corner."""
    corner_before_m: float = 1.0
    """The corner speed holds from this far before a corner (along the plan) ..."""
    corner_after_m: float = 0.3
    """... to this far past it ..."""
    corner_ramp_m: float = 1.0
    """... and the limit rises linearly to the cruise speed over this distance before that."""
    lane_shift_m: float = 0.9
    """Largest sideways shift of the carrot off the plan (ours, 0 = off, as the paper):
    where the plan's line ahead is blocked (an obstacle within the avoidance radius of it
    within ``lane_check_m``), the carrot moves sideways to the nearest offset whose line
    is clear, keeping to the side chosen before. Eq. 5 alone steers towards the carrot on
    the plan, right behind an obstacle standing in the middle of a corridor: both ways
    round score alike, and the robot would swing from one to the other and never pass."""
    lane_check_m: float = 2.5
    """... looking this far ahead along a straight stretch of the plan."""
    side_hysteresis: float = 1.0
    """Keep swerving to the side chosen before while a direction there scores at least
    this fraction of Eq. 5's best (1 = off, as the paper; below 1 it steadies the
    approach to a standing person but can hold a swerve into a person coming round a
    corner)."""
    near_wall_tol_m: float = 0.1
    """A near-field sight line passing this close to a map wall (through the pose
    estimate) is taken as that wall, not an unmapped obstacle (``command``)."""
    memory_beside_s: float = 10.0
    """Remembered points out of the camera's view within ``memory_beside_m`` of the robot
    count this long for the avoidance, past ``memory_s``: a robot rounding furniture
    drives beside what it saw of it for several seconds (turning round an unmapped
    chair's end keeps the chair out of view for about 5 s, longer than ``memory_s``,
    while the robot's side passes it). People who walk on leave their points behind this long at most, and only while
    the robot stays near them. 0 = off (``memory_s`` alone)."""
    memory_beside_m: float = 1.0
    """... this far from the robot's centre at most."""
    memory_blind_s: float = 10.0
    """Remembered points right in front of the robot, closer than the camera sees, count
    until the camera sees their place again, but this long at most. The memory covers the seconds between losing sight of something and getting away
    from it (a back-off brings it into view); something standing that close for longer
    hides the floor in front, which the near field checks every frame. A point the robot
    cannot look at again (its back-off ended short, its own trail leading sideways)
    would otherwise hold it for good: the edge of a person who walked across a 0.9 m
    door, sensed as they went, blocks the door for a robot that needs 0.8 m long after
    they have gone, and a robot that cannot back off far enough to see the place again
    backs off and returns to it without end."""
    shadow_m: float = 0.6
    """Each sensed point within ``memory_radius_m`` also marks the space behind it, seen
    from the camera, this deep as occupied until the camera looks there
    (:mod:`autonomy.navigation.obstacle_memory`): the camera sees only an obstacle's near
    faces, and a robot rounding it meets the far ones (an unmapped chair's far corner,
    never seen, is where the robot's side passes as it turns round the chair). 0.6 m covers the far side of the
    building's chairs and boxes and most of its tables; 0 = off."""
    memory_cell_m: float = 0.05
    """Remembered points are kept on a grid of this size (one point per cell)."""
    memory_radius_m: float = 2.0
    """Only obstacles sensed within this distance of the robot are remembered: the
    blind zone beside and right in front of the robot is what the memory covers."""

    def __post_init__(self) -> None:
        require_positive(
            self, "navigator.", "cruise_speed_mps", "lookahead_m", "arrival_radius_m", "heading_gain", "max_turn_rate_rad_s", "stuck_time_s"
        )
        require_non_negative(
            self, "navigator.", "backoff_time_s", "backoff_speed_mps", "stuck_progress_m", "memory_s", "unseen_speed_mps",
            "backoff_check_m", "backoff_clearance_m", "corner_speed_mps", "corner_angle_rad", "corner_before_m",
            "map_blind_spots_m", "map_clearance_m", "proximity_speed_mps", "proximity_gap_m", "proximity_range_m",
            "corner_after_m", "corner_ramp_m", "near_wall_tol_m", "backoff_memory_s", "lane_shift_m", "lane_check_m",
            "trail_s", "trail_tolerance_m", "look_back_m", "blocked_edge_s", "blocked_wait_s", "blocked_check_m",
            "long_detour_m", "long_detour_wait_s",
            "narrow_lookahead_m", "narrow_slack_m", "narrow_before_m", "narrow_horizon_m",
            "memory_beside_s", "memory_beside_m", "memory_blind_s", "shadow_m", "coastal_weight",
            "shortcut_clearance_m", "shortcut_blind_slack_m",
        )
        if self.narrow_lookahead_m > self.lookahead_m:
            raise InputError(
                f"navigator.narrow_lookahead_m: expected at most lookahead_m ({self.lookahead_m!r}), got {self.narrow_lookahead_m!r}"
            )
        require_positive(self, "navigator.", "memory_cell_m", "memory_radius_m", "look_turn_rate_rad_s", "coastal_range_m")
        # The memory merges cells on a dense grid over memory_radius_m + 0.5 (obstacle_memory.py).
        finest = (self.memory_radius_m + MEMORY_KEEP_MARGIN_M) / 250
        if self.memory_cell_m < finest:
            raise InputError(
                f"navigator.memory_cell_m: expected at least (memory_radius_m + {MEMORY_KEEP_MARGIN_M}) / 250 = {finest:.4g} m, "
                f"got {self.memory_cell_m!r}"
            )


@dataclass
class NavCommand:
    """What the navigator decided this frame."""

    velocity: np.ndarray
    """Body-frame command (vx, vy, omega)."""
    state: str
    """idle, turning, driving, blocked, recovering, looking or arrived."""
    carrot: np.ndarray = field(default_factory=lambda: np.zeros(2))
    """Carrot in the world frame."""
    desired_rad: float = 0.0
    """Carrot direction in the robot frame."""
    theta_star_rad: float = 0.0
    """Direction chosen by the avoidance (robot frame)."""
    open_length_m: float = math.inf
    """Open path length along theta*."""
    fan: tuple[np.ndarray, np.ndarray] | None = None
    """(angles, open lengths) of the avoidance fan, for visualisation."""
    near_points: int = 0
    """Near-field points (closer than the camera's minimum range) among the obstacles."""
