"""The robot stack's configuration: everything it needs besides the map."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from autonomy.common.errors import require_non_negative, require_positive
from autonomy.localization.active_localization import ActiveLocalizationConfig
from autonomy.localization.cgr import CGRConfig
from autonomy.localization.health import HealthConfig
from autonomy.localization.missing_walls import MissingWallsConfig
from autonomy.localization.observation import ObservationConfig
from autonomy.localization.relocalization import RelocalizationConfig
from autonomy.localization.view_check import ViewCheckConfig
from autonomy.maps.raycast import VisibilityGridConfig
from autonomy.navigation.avoidance import AvoidanceConfig
from autonomy.navigation.config import NavigatorConfig
from autonomy.perception.camera import DepthCamera
from autonomy.perception.fspf import FSPFConfig
from autonomy.perception.mount_check import MountCheckConfig

#: The visibility grid the stack localizes with: 0.5 m cells, scene lines to 6 m (the
#: Kinect sees 4 m; the margin keeps lines a refined particle may reach).
LOCALIZATION_GRID = VisibilityGridConfig(cell_m=0.5, max_range_m=6.0)


@dataclass(frozen=True)
class LocalizationConfig:
    """CGR localization on FSPF points (BV2012, Section IV)."""

    enabled: bool = True
    """Run CGR every frame; off: the estimate is dead reckoning from the odometry."""
    cgr: CGRConfig = field(default_factory=CGRConfig)
    """Particle filter parameters."""
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    """Point-cloud observation model parameters (Eq. 1-2)."""
    grid: VisibilityGridConfig = LOCALIZATION_GRID
    """Visibility grid for the analytic ray cast (Algorithm 2)."""


@dataclass(frozen=True)
class RecoveryConfig:
    """Lost detection and global relocalization (ours; the papers' operator re-localized
    the robot by hand): :mod:`autonomy.localization.health`, :mod:`autonomy.localization.relocalization`."""

    enabled: bool = True
    """Watch the localization's health and relocalize globally when lost."""
    health: HealthConfig = field(default_factory=HealthConfig)
    """The lost and blind tests."""
    relocalization: RelocalizationConfig = field(default_factory=RelocalizationConfig)
    """Scan, search and decision."""
    check_mount: bool = True
    """Watch the floor for a tilted camera mount and correct the mount FSPF uses
    (:mod:`autonomy.perception.mount_check`)."""
    mount_check: MountCheckConfig = field(default_factory=MountCheckConfig)
    """The mount self-check's parameters."""
    view: ViewCheckConfig = field(default_factory=ViewCheckConfig)
    """The check of each view against the odometry (:mod:`autonomy.localization.view_check`), which
    tells the health monitor that the robot was carried."""
    missing: MissingWallsConfig = field(default_factory=MissingWallsConfig)
    """Which pixels expect a mapped wall, for the health monitor's missing-wall test
    (:mod:`autonomy.localization.missing_walls`)."""
    restart_std_xy_m: float = 0.15
    """CGR restarts around an accepted mode with this position spread ..."""
    restart_std_theta_rad: float = math.radians(4.0)
    """... and this heading spread."""
    explore_check_m: float = 3.0
    """An exploring drive's plan must be clear of the scan's points for this far (robot
    radius less a little Kinect noise)."""
    settle_s: float = 2.0
    """After a relocalization the robot turns in place this long before it drives on,
    while CGR, restarted around the mode, converges: the map's walls in the camera's
    blind spots are placed through the pose, and an accepted mode can be 0.2 m off."""
    explore_after_s: float = 12.0
    """Still undecided after looking this long, the robot drives on the best mode's
    belief to a place ``explore_m`` away (the modes agree on what is near, so the way
    there is the same in all of them), looking as it goes, until the scan decides."""
    explore_m: float = 6.0
    """How far the exploring drive goes before the robot looks round again ..."""
    explore_timeout_s: float = 20.0
    """... or how long it may take (a drive that is blocked looks round again and then
    tries another place)."""
    active: ActiveLocalizationConfig = field(default_factory=ActiveLocalizationConfig)
    """Which exploring drive tells the modes apart (:mod:`autonomy.localization.active_localization`)."""

    def __post_init__(self) -> None:
        require_non_negative(self, "recovery.", "restart_std_xy_m", "restart_std_theta_rad", "settle_s")
        require_positive(self, "recovery.", "explore_after_s", "explore_m", "explore_timeout_s", "explore_check_m")


@dataclass(frozen=True)
class StackConfig:
    """Everything the robot-side stack needs besides the map."""

    camera: DepthCamera = field(default_factory=DepthCamera)
    """The depth camera: intrinsics, mount and valid range (one source for all modules)."""
    fspf: FSPFConfig = field(default_factory=FSPFConfig)
    """FSPF parameters (BV2012 Table I)."""
    localization: LocalizationConfig = field(default_factory=LocalizationConfig)
    """CGR localization."""
    avoidance: AvoidanceConfig = field(default_factory=AvoidanceConfig)
    """Obstacle avoidance (Eq. 3-5), the robot radius and the near field."""
    navigator: NavigatorConfig = field(default_factory=NavigatorConfig)
    """Carrot following, speed limits, memory and recovery."""
    navigate: bool = True
    """Run the navigator (off: perception and localization only, as in offline replays)."""
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)
    """Lost detection and global relocalization (needs localization)."""

    @property
    def recovers(self) -> bool:
        """Whether the stack watches its localization and relocalizes when lost (recovery
        on, with localization to watch): needed to start with an unknown pose."""
        return self.recovery.enabled and self.localization.enabled
