"""What the robot stack tells its caller: one :class:`StackOutput` a frame.

A caller (a simulation's loop, a gym env, a benchmark, a real robot's driver) reads the
stack only through these objects, so what it reads is one frame's state, fixed when the
output was made: arrays the stack changes in place later (the estimate, the odometry,
the particles) are copied; objects the stack replaces rather than changes (the
perception, the plan, the health sample, CGR's statistics and refinement sets, the last
map search) are shared.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from autonomy.localization.cgr import UpdateStats
from autonomy.localization.health import HealthSample
from autonomy.localization.relocalization import SearchResult
from autonomy.navigation.config import NavCommand
from autonomy.navigation.plan import Plan
from autonomy.stack.state import Perception


@dataclass(frozen=True, eq=False)
class PlanView:
    """The navigator's plan and counters as of one output.

    The plan is shared, not copied: a plan is never changed after it is made (a re-plan
    makes a new one). The metres left on it are measured only when read (a projection
    on the plan): of the stack's callers only a mission's leg budget needs them."""

    plan: Plan
    """The plan followed (none: no goal yet)."""
    measured_from: np.ndarray | None
    """The position (x, y) :attr:`remaining_m` is measured from: the pose the decision
    was made on. None: :attr:`length_m` is the figure (:meth:`RobotStack.set_goal`)."""
    length_m: float
    """Metres ahead when :attr:`measured_from` is None."""
    replans: int
    """Plans made again to the same goal so far (recoveries, blocks, pose jumps)."""
    recoveries: int
    """Recoveries started so far (the robot was stuck)."""
    blocked_edges: int
    """Graph edges marked blocked so far."""

    @property
    def nodes(self) -> tuple[int, ...]:
        """The plan's graph nodes (it runs from the pose to the first, then on)."""
        return tuple(self.plan.nodes)

    @property
    def path(self) -> np.ndarray:
        """The plan's polyline (K, 2), world frame, the pose it was made from first."""
        return self.plan.path

    @cached_property
    def remaining_m(self) -> float:
        """Metres of the plan still ahead of the pose (0 without a plan)."""
        if self.measured_from is None:
            return self.length_m
        return self.plan.remaining_m(self.measured_from)


@dataclass(frozen=True)
class Refinement:
    """CGR's particle sets of its last update, for viewers: before and after the
    refinement, and the weights after it."""

    before: np.ndarray
    after: np.ndarray
    weights: np.ndarray


@dataclass(frozen=True, eq=False)
class StackOutput:
    """One frame of the stack: the command, the belief, and everything a viewer, a report
    or a supervisor reads."""

    command: NavCommand | None
    """The navigator's decision for the next motion (None when the stack does not navigate)."""
    estimate: np.ndarray
    """Pose estimate (x, y, theta) in the map frame."""
    spread: tuple[float, float]
    """(position spread m, heading spread rad) of the belief; (0, 0) for dead reckoning."""
    perception: Perception
    """The last usable frame's FSPF result, observation points, obstacles and near field."""
    timings_s: dict[str, float]
    """Seconds spent in each stage this frame: fspf, obstacles, localization, navigation."""
    plan: PlanView | None
    """The navigator's plan after the decision (None when the stack does not navigate)."""
    localizing: bool
    """Whether the belief is CGR's (else dead reckoning)."""
    relocalizing: bool
    """True while the robot is lost and searching the map."""
    health_state: str
    """ok, blind, lost (the moment it is noticed) or relocalizing; ok without recovery."""
    health_sample: HealthSample | None
    """The health monitor's last sample (None without recovery)."""
    events: tuple[dict, ...]
    """What the recovery did since the last reset, oldest first: {"t", "event": lost |
    relocalized | blind | seeing | mount corrected, ...}."""
    frame_fault: str
    """What was wrong with this frame ('' nothing): dropped, stale, invalid or corrupt."""
    frames_rejected: dict[str, int]
    """Frames dropped, stale, invalid and corrupt since the stack was made."""
    cgr_stats: UpdateStats | None
    """What CGR's update did this frame (None: no update)."""
    correction: tuple[float, float] | None
    """How far this frame's update moved the belief beyond the odometry (world x, y)."""
    odometry: np.ndarray
    """Dead reckoning from the odometry alone (x, y, theta)."""
    particles: np.ndarray | None
    """CGR's particles (n, 3) (None without localization)."""
    refinement: Refinement | None
    """CGR's last update's particle sets (None without localization)."""
    last_search: SearchResult | None
    """The relocalization's last map search (None before the first)."""
    correspondences: tuple[np.ndarray, np.ndarray] | None
    """Asked for (:meth:`RobotStack.step`), the scene lines visible from the estimate and
    each observation point's line index (-1: none); else None."""
    known: np.ndarray | None = None
    """Asked for (:meth:`RobotStack.step`'s ``known_m``), what the navigator knows round
    the robot within that radius, robot frame of the estimate: the obstacles of its
    decision (obstacle memory, this frame's, near field) and the map's walls
    (:meth:`Navigator.known_points`); else None."""

    @property
    def velocity(self) -> np.ndarray:
        """Body-frame velocity command (vx, vy, omega); zero when not navigating."""
        return np.zeros(3) if self.command is None else self.command.velocity
