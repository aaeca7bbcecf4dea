"""The faults a run is configured with, and when each is due.

A scenario's ``[faults]`` table is a :class:`FaultsConfig`: explicit events
(:class:`FaultEvent`, by distance driven or simulated time) and/or one fault every
``every_m`` metres, with each kind's parameters (:class:`FaultParams`).
:class:`FaultSchedule` says which are due, :func:`fault_rng` gives the run's fault stream,
and :func:`fault_actors` the people and furniture the world must hold for them. What each
kind does, and the injector that applies them, are in :mod:`sim.simulator.faults`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from autonomy.common.errors import InputError, require_int, require_non_negative, require_positive
from sim.simulator.actors import PARK_XY, Furniture, Person, parked_person

FAULT_KINDS = ("kidnap", "blackout", "dropped", "corrupt_nan", "stale", "slip", "tilt", "crowd", "blockage")
"""Every fault kind, as named in a scenario."""

KIND_PARAMS: dict[str, tuple[str, ...]] = {
    "kidnap": (),
    "blackout": ("blackout_s",),
    "dropped": ("burst_s", "drop_probability"),
    "corrupt_nan": ("burst_s", "nan_fraction", "nan_rows"),
    "stale": ("burst_s",),
    "slip": ("slip_s", "slip_speed_mps", "bump_m", "bump_deg"),
    "tilt": ("tilt_deg",),
    "crowd": ("crowd_size", "crowd_s", "crowd_radius_m"),
    "blockage": ("blockage_s",),
}
"""The parameters each kind uses (an event may override these only)."""

DURATION_PARAM = {
    "blackout": "blackout_s",
    "dropped": "burst_s",
    "corrupt_nan": "burst_s",
    "stale": "burst_s",
    "slip": "slip_s",
    "crowd": "crowd_s",
    "blockage": "blockage_s",
}
"""How long each kind lasts; kidnap is instantaneous, tilt is for the rest of the run."""

UNSET = -1
"""An event's parameter left at this takes the ``[faults]`` table's value."""

#: Width of one panel of a blockage (a slab is as many side by side as the corridor needs).
PANEL_WIDTH_M = 0.5
#: Parked fault furniture stands in a row this far from ``PARK_XY`` (apart from the env's).
PARK_ROW_OFFSET_M = -50.0
#: Simulated time accumulates physics steps with rounding: a fault at (or ending at) time t
#: is due at the frame whose time is t within this.
TIME_EPS_S = 1e-6
#: The fault stream's spawn key (apart from every stream of :class:`sim.simulator.step.EpisodeSeeds`).
FAULT_STREAM = 0xFA017


@dataclass(frozen=True)
class FaultParams:
    """Each kind's parameters (the defaults of every event of that kind)."""

    blackout_s: float = 5.0
    """blackout: how long no frame has a valid pixel."""
    burst_s: float = 3.0
    """dropped, corrupt_nan, stale: how long the burst lasts."""
    drop_probability: float = 0.5
    """dropped: chance of each frame of the burst being lost."""
    nan_fraction: float = 0.3
    """corrupt_nan: fraction of the pixels that are NaN."""
    nan_rows: int = 8
    """corrupt_nan: whole rows of NaN per frame."""
    slip_s: float = 2.0
    """slip: how long the wheels spin."""
    slip_speed_mps: float = 0.5
    """slip: forward speed the odometry reports on top of the true motion."""
    bump_m: float = 0.3
    """slip: how far the robot is pushed at the start, unseen by the odometry (0 = no bump)."""
    bump_deg: float = 15.0
    """slip: how far it is turned at the start (degrees, random sign)."""
    tilt_deg: float = 4.0
    """tilt: change of the camera's orientation (degrees, split between pitch and roll)."""
    crowd_size: int = 12
    """crowd: how many people appear."""
    crowd_s: float = 60.0
    """crowd: how long they walk around the robot before they leave."""
    crowd_radius_m: float = 8.0
    """crowd: their routes stay within this graph distance of the robot's nearest node."""
    blockage_s: float = 300.0
    """blockage: how long it stays (0 = the rest of the run)."""

    def check_params(self, prefix: str, names: tuple[str, ...] | None = None) -> None:
        """One-line InputError naming ``prefix + name`` for a bad value of the parameters
        ``names`` (default: all)."""
        names = tuple(f.name for f in fields(FaultParams)) if names is None else names
        positive = ("blackout_s", "burst_s", "slip_s", "crowd_s", "crowd_radius_m")
        require_positive(self, prefix, *(n for n in names if n in positive))
        require_non_negative(self, prefix, *(n for n in names if n in ("slip_speed_mps", "bump_m", "bump_deg", "tilt_deg", "blockage_s")))
        require_int(self, prefix, *(n for n in names if n in ("nan_rows", "crowd_size")), minimum=0)
        for name in ("drop_probability", "nan_fraction"):
            v = getattr(self, name)
            if name in names and not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0.0 <= v <= 1.0):
                raise InputError(f"{prefix}{name}: expected a number in [0, 1], got {v!r}")


@dataclass(frozen=True)
class FaultEvent:
    """One fault at a given distance driven or simulated time, with optional parameters
    (each ``-1`` takes the ``[faults]`` table's value; only the kind's own may be set)."""

    kind: str = ""
    """One of ``FAULT_KINDS``."""
    at_m: float = UNSET
    """Fires when the robot has driven this far (m); -1: by time."""
    at_s: float = UNSET
    """Fires at this simulated time (s); -1: by distance."""
    blackout_s: float = UNSET
    """See :class:`FaultParams`."""
    burst_s: float = UNSET
    """See :class:`FaultParams`."""
    drop_probability: float = UNSET
    """See :class:`FaultParams`."""
    nan_fraction: float = UNSET
    """See :class:`FaultParams`."""
    nan_rows: int = UNSET
    """See :class:`FaultParams`."""
    slip_s: float = UNSET
    """See :class:`FaultParams`."""
    slip_speed_mps: float = UNSET
    """See :class:`FaultParams`."""
    bump_m: float = UNSET
    """See :class:`FaultParams`."""
    bump_deg: float = UNSET
    """See :class:`FaultParams`."""
    tilt_deg: float = UNSET
    """See :class:`FaultParams`."""
    crowd_size: int = UNSET
    """See :class:`FaultParams`."""
    crowd_s: float = UNSET
    """See :class:`FaultParams`."""
    crowd_radius_m: float = UNSET
    """See :class:`FaultParams`."""
    blockage_s: float = UNSET
    """See :class:`FaultParams`."""

    def overrides(self) -> dict[str, float]:
        """The parameters this event sets."""
        return {f.name: getattr(self, f.name) for f in fields(FaultParams) if getattr(self, f.name) != UNSET}

    def check(self, key: str) -> None:
        """One-line InputError naming ``key`` (e.g. ``faults.events[0]``) for a bad event."""
        check_kind(self.kind, f"{key}.kind")
        if (self.at_m == UNSET) == (self.at_s == UNSET):
            raise InputError(f"{key}: give exactly one of 'at_m' (distance driven) or 'at_s' (simulated time), each >= 0")
        for name in ("at_m", "at_s"):
            v = getattr(self, name)
            if v != UNSET and not v >= 0:
                raise InputError(f"{key}.{name}: expected a number >= 0, got {v!r}")
        own = KIND_PARAMS[self.kind]
        for name in self.overrides():
            if name not in own:
                theirs = ", ".join(own) if own else "none"
                raise InputError(f"{key}.{name}: not a parameter of '{self.kind}' (its parameters: {theirs})")


def check_kind(kind: str, key: str) -> None:
    if kind not in FAULT_KINDS:
        raise InputError(f"{key}: unknown fault {kind!r} (expected one of: {', '.join(FAULT_KINDS)})")


@dataclass(frozen=True)
class FaultsConfig(FaultParams):
    """Faults of a run: explicit events and/or one every ``every_m`` metres; the
    parameters of each kind (flat fields, from :class:`FaultParams`). Default: none."""

    events: tuple[FaultEvent, ...] = ()
    """Explicit faults, each fired once (``[[faults.events]]`` tables)."""
    every_m: float = 0.0
    """A fault every this many metres driven (0 = none), the kinds in a seeded shuffled
    order, each round a new order."""
    kinds: tuple[str, ...] = FAULT_KINDS
    """The kinds ``every_m`` cycles through."""
    start_m: float = 0.0
    """Distance of the first periodic fault (0 = at ``every_m``)."""
    blockage_depth_m: float = 0.05
    """Depth of a blockage along the corridor: 0.05 a door slab, 0.5 a row of boxes."""
    blockage_height_m: float = 2.0
    """Height of a blockage."""
    blockage_max_width_m: float = 3.0
    """Widest corridor a blockage spans (sets how many panels the world holds)."""

    def __post_init__(self) -> None:
        self.check_params("faults.")
        require_non_negative(self, "faults.", "every_m", "start_m")
        require_positive(self, "faults.", "blockage_depth_m", "blockage_height_m")
        if not self.blockage_max_width_m >= PANEL_WIDTH_M:
            raise InputError(f"faults.blockage_max_width_m: expected a number >= {PANEL_WIDTH_M}, got {self.blockage_max_width_m!r}")
        for i, kind in enumerate(self.kinds):
            check_kind(kind, f"faults.kinds[{i}]")
        if self.every_m > 0 and not self.kinds:
            raise InputError("faults.kinds: expected at least one kind with every_m > 0")
        for i, ev in enumerate(self.events):
            ev.check(f"faults.events[{i}]")
            self.params_of(ev).check_params(f"faults.events[{i}].", tuple(ev.overrides()))

    @property
    def enabled(self) -> bool:
        """Whether any fault is configured."""
        return bool(self.events) or self.every_m > 0

    def defaults(self) -> FaultParams:
        """The table's parameters alone."""
        return FaultParams(**{f.name: getattr(self, f.name) for f in fields(FaultParams)})

    def params_of(self, event: FaultEvent) -> FaultParams:
        """An event's parameters: its own where set, else the table's."""
        return replace(self.defaults(), **event.overrides())

    def uses(self, kind: str) -> list[FaultParams]:
        """The parameters of every configured use of a kind (periodic: the table's)."""
        out = [self.params_of(e) for e in self.events if e.kind == kind]
        if self.every_m > 0 and kind in self.kinds:
            out.append(self.defaults())
        return out

    def n_panels(self) -> int:
        """Panels of a blockage the world holds."""
        return math.ceil(self.blockage_max_width_m / PANEL_WIDTH_M - 1e-9)


def fault_rng(seed: int) -> np.random.Generator:
    """The fault stream of a run's seed, independent of every stream of
    :class:`sim.simulator.step.EpisodeSeeds` (its own spawn key)."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(FAULT_STREAM,)))


def fault_actors(cfg: FaultsConfig) -> tuple[tuple[Furniture, ...], tuple[Person, ...]]:
    """Furniture and people the configured faults use, parked outside the building: append
    them to the world's actors when it is built (empty when no crowd or blockage is
    configured, so such a world is the same as without faults)."""
    people = max((p.crowd_size for p in cfg.uses("crowd")), default=0)
    furniture: tuple[Furniture, ...] = ()
    if cfg.uses("blockage"):
        size = (cfg.blockage_depth_m, PANEL_WIDTH_M, cfg.blockage_height_m)
        furniture = tuple(
            Furniture(kind="box", x=PARK_XY[0] - 10.0 * i, y=PARK_XY[1] + PARK_ROW_OFFSET_M, size=size) for i in range(cfg.n_panels())
        )
    return furniture, tuple(parked_person() for _ in range(people))


class FaultSchedule:
    """Which faults are due: explicit events once each, and one every ``every_m`` metres
    from ``start_m`` up to (not including) ``until_m``, the kinds in a shuffled order drawn
    from ``rng`` each round. ``until_m`` is a long run's distance: a run that goes on past
    it to see a recovery to its end gets no new periodic faults."""

    def __init__(self, cfg: FaultsConfig, rng: np.random.Generator, until_m: float = math.inf) -> None:
        self.cfg = cfg
        self.rng = rng
        self.until_m = float(until_m) if until_m > 0 else math.inf
        self._pending = list(range(len(cfg.events)))
        self._next_m = (cfg.start_m or cfg.every_m) if cfg.every_m > 0 else math.inf
        self._order: list[str] = []

    def due(self, t: float, distance_m: float) -> list[tuple[str, FaultParams, str]]:
        """(kind, parameters, trigger) of every fault due now, explicit events first (at
        most one periodic fault per call)."""
        out = []
        if self._pending:
            for i in list(self._pending):
                ev = self.cfg.events[i]
                if (ev.at_m != UNSET and distance_m >= ev.at_m) or (ev.at_s != UNSET and t >= ev.at_s - TIME_EPS_S):
                    self._pending.remove(i)
                    out.append((ev.kind, self.cfg.params_of(ev), f"events[{i}]"))
        if distance_m >= self._next_m and self._next_m < self.until_m:
            self._next_m += self.cfg.every_m
            if not self._order:
                self._order = [str(k) for k in self.rng.permutation(np.array(self.cfg.kinds))]
            out.append((self._order.pop(0), self.cfg.defaults(), "every_m"))
        return out
