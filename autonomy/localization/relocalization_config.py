"""The parameters of the global relocalization: the scan, the coarse search, the modes'
scoring and the decision that :mod:`autonomy.localization.relocalization` describes and
runs, checked when the configuration is built."""

from __future__ import annotations

from dataclasses import dataclass

from autonomy.common.errors import require_int, require_non_negative, require_positive


@dataclass(frozen=True)
class RelocalizationConfig:
    """Scan, search and decision parameters of the global relocalization."""

    grid_step_m: float = 0.4
    """Coarse search: hypothesis positions every this far over the free space."""
    heading_step_deg: float = 5.0
    """Coarse search: hypothesis headings every this many degrees."""
    coarse_points: int = 160
    """Scan points scored per coarse hypothesis (an even subsample)."""
    coarse_seeds: int = 4000
    """The best this-many coarse hypotheses are re-ranked with their sight through walls
    (and of the floor) before the distinct ones are refined. On cost alone, a scan of
    furniture and one long wall at an open hall's edge can rank the true place more than
    a thousand places down, behind offices whose walls the furniture fits."""
    cost_seeds: int = 20
    """... and the best this-many by cost alone are refined as well, unthinned: at a
    coarse pose, half a grid step and half a heading step off, rays slip past pillars
    and the ends of walls, so in a hall of pillars the ranking by sight through walls
    can sink the true place behind open spaces the scan fits loosely; and two seeds a
    grid step apart can fall into different basins (a doubled wall line), which only
    the refinement tells apart. 0: the ranked seeds alone."""
    coarse_robust_m: float = 0.5
    """Cost saturation distance c of the coarse search (a coarse hypothesis is up to half
    a grid step and half a heading step off)."""
    fine_robust_m: float = 0.2
    """Cost saturation distance of the refinement and the decision."""
    modes: int = 40
    """Modes kept and refined."""
    mode_separation_m: float = 1.0
    """Modes closer than this ..."""
    mode_separation_deg: float = 25.0
    """... and this in heading are the same mode."""
    scan_cell_m: float = 0.05
    """The scan keeps one point per cell of this size."""
    max_scan_points: int = 6000
    """The scan keeps at most this many points (the newest)."""
    min_scan_points: int = 150
    """No search before the scan has this many points ..."""
    min_wall_m: float = 1.5
    """A wall: a straight run of the scan's points at least this long
    (:mod:`autonomy.localization.straight_runs`); the faces of the atrium's pillars and of the
    furniture the map lacks are shorter."""
    min_wall_points: int = 40
    """Looked round, the robot drives to find walls while fewer of the scan's points than
    this lie on walls (2 m of wall at 5 cm cells; 0: only while the scan is too small to
    search). A scan of pillars and furniture fits no place clearly, the true one
    included, however long the robot looks there."""
    min_sweep_deg: float = 300.0
    """... and the robot has turned this far (or moved ``min_travel_m``) while looking."""
    min_travel_m: float = 2.0
    """Distance that counts as looking as much as the sweep."""
    accept_cost: float = 0.2
    """The best mode must explain the scan this well (its score: the mean robust cost, 0 =
    every point on a wall, plus the sight-through-walls term), or up to
    ``accept_lead_cost`` with a clear lead ..."""
    accept_margin_points: float = 40.0
    """... and every other mode must cost at least this much more in total over the scan
    (the mean cost difference times the scan's points: what that many points lying on a
    wall in one mode and off every wall in the other add up to) ..."""
    accept_margin: float = 0.02
    """... and at least this much more per point."""
    accept_lead_cost: float = 0.4
    """A best mode scoring worse than ``accept_cost`` (up to this) is accepted when every
    other mode scores worse by ``accept_lead`` per point (and ``accept_margin_points``
    over the scan): a long look's scan, placed by dead reckoning over metres of
    exploring, fits no place sharply, and clutter raises every mode's score alike; what
    tells the place is the lead."""
    accept_lead: float = 0.15
    """The lead a mode scoring between ``accept_cost`` and ``accept_lead_cost`` needs over
    every other mode (and the belief before the alarm must be ruled out:
    :meth:`autonomy.localization.relocalization.GlobalLocalizer.lead_allowed`). It lies
    above the lead of every wrong mode measured on the tuning seeds (up to 0.14, each
    scoring under ``accept_cost``)."""
    max_through: float = 0.1
    """... and at most this fraction of the latest frame's points may lie beyond the map's
    walls seen from it."""
    search_every_s: float = 1.0
    """Repeat the search this often while undecided (the scan grows)."""
    explain_m: float = 0.15
    """The check of the latest frame from a mode: a point within this of the first wall
    on its ray is explained ... (as :class:`autonomy.localization.health.HealthConfig`)"""
    through_m: float = 0.4
    """... and one this far beyond it is seen through the wall (the scan's points: this
    far along their ray behind a wall it crosses, and ``through_depth_m`` ...)"""
    through_depth_m: float = 0.2
    """... from the wall's line. The scan is placed by dead reckoning: a degree of drift
    moves a point 4 m away 7 cm off its wall, 0.4 m along its ray when the wall is seen
    10 degrees off it. 0 counts along the ray alone."""
    confirmations: int = 2
    """A mode is accepted once it has passed the decision in this many searches in a row
    (within ``mode_separation_m`` and ``mode_separation_deg`` of itself)."""
    prior_cost: float = 0.45
    """A false alarm: the belief before the alarm is kept when it explains the scan at
    least this well and within ``accept_margin`` of the best mode."""
    prior_lead_cost: float = 0.8
    """... or, scoring worse than ``prior_cost`` (up to this: a hall full of furniture the
    map lacks), when every mode elsewhere scores worse by the acceptance margins. A
    kidnapped robot's old belief loses to the place it is at by far more (0.5 or more
    on the tuning seeds)."""
    through_weight: float = 3.0
    """A mode's score is its cost plus this times the fraction of the scan's points it
    sees through the map's walls (each point's ray from where the camera stood when it
    saw it). Clutter can only hide walls, so one point seen through a wall speaks
    against a mode more than an unexplained one: scans in open halls full of furniture
    otherwise fit the many walls of offices elsewhere better than the hall itself."""
    piece_s: float = 10.0
    """A mode is scored on the scan in pieces: the points last seen within each span of
    this many seconds, each piece refined on its own from the mode's pose (0: the scan
    as one piece). The scan is placed by dead reckoning, and after a minute of turning
    and driving its older walls lie a degree or two off the newer ones: a room's true
    place then fits no better than the same room turned round."""
    piece_shift_m: float = 0.3
    """A piece's own refinement is kept only within this of the mode's position ..."""
    piece_turn_deg: float = 3.0
    """... and this of its heading (else the piece is scored at the mode's pose):
    what a minute of dead reckoning drifts, not a different place."""
    floor_weight: float = 3.0
    """A mode's score adds this times the fraction of the floor points seen while
    looking (:mod:`autonomy.perception.floor_rays`) whose sight line crosses one of the mode's
    walls (0: the floor is not used) ... The floor is seen only
    where no wall stands in between: at an open hall's edge, facing furniture the map
    lacks, a scan can fit offices elsewhere better than its true place (0.16 against
    0.29), but their walls stand across a quarter to a half of the sight lines into the
    hall, and the true place's across none ..."""
    floor_jamb_m: float = 0.15
    """... counting a wall only where the sight line crosses it this far from its ends.
    The scan is placed by dead reckoning, and a sight line through a door passes its
    jamb within centimetres: from an office's true place a few per cent of the sight
    lines cross a wall, every one within 0.1 m of a door's jamb, and counted, they let
    the office next door, or its mirror image in the other block, win. A larger margin
    leaves a wrong place too few of its crossings: at 0.2 m, a place along the atrium's
    south wall stays within the acceptance lead of the true one."""
    floor_stride_px: int = 16
    """One floor point per this-many image columns and frame (40 on a 640-pixel row) ..."""
    floor_cell_m: float = 0.25
    """... and the scan keeps one per cell of this size (the newest): a look round sees
    the floor on a ring about 4 m round, some 500 cells."""

    def __post_init__(self) -> None:
        require_positive(
            self, "recovery.relocalization.", "grid_step_m", "heading_step_deg", "coarse_robust_m", "fine_robust_m",
            "mode_separation_m", "mode_separation_deg", "scan_cell_m", "accept_cost", "search_every_s", "min_travel_m",
            "accept_margin_points", "accept_margin", "accept_lead_cost", "accept_lead",
        )
        require_non_negative(
            self, "recovery.relocalization.", "min_sweep_deg", "max_through", "prior_cost", "prior_lead_cost", "explain_m", "through_m",
            "through_depth_m", "through_weight", "piece_s", "piece_shift_m", "piece_turn_deg", "floor_weight", "floor_jamb_m",
        )
        require_int(self, "recovery.relocalization.", "floor_stride_px", minimum=1)
        require_int(self, "recovery.relocalization.", "coarse_seeds", minimum=1)
        require_int(self, "recovery.relocalization.", "cost_seeds", minimum=0)
        require_positive(self, "recovery.relocalization.", "floor_cell_m")
        require_int(self, "recovery.relocalization.", "coarse_points", minimum=10)
        require_int(self, "recovery.relocalization.", "modes", minimum=1)
        require_int(self, "recovery.relocalization.", "confirmations", minimum=1)
        require_int(self, "recovery.relocalization.", "max_scan_points", minimum=100)
        require_int(self, "recovery.relocalization.", "min_scan_points", minimum=10)
        require_int(self, "recovery.relocalization.", "min_wall_points", minimum=0)
        require_positive(self, "recovery.relocalization.", "min_wall_m")
