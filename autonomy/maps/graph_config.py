"""Settings of the navigation graphs made from the walls (:mod:`autonomy.maps.graph_builder`)."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

from autonomy.common.constants import SAFETY_MARGIN_M
from autonomy.common.errors import require_positive
from autonomy.maps.freespace import FreeSpaceConfig

__all__ = ["GraphBuildConfig"]


@dataclass(frozen=True)
class GraphBuildConfig:
    """Settings of the automatic navigation graph (metres, m/s)."""

    free_space: FreeSpaceConfig = field(default_factory=FreeSpaceConfig)
    """Grid, robot radius and inside/outside settings."""
    margin_m: float = SAFETY_MARGIN_M
    """Every edge keeps the robot radius plus this from every wall: the obstacle
    avoidance's own margin, so that it lets the robot through every edge (a passage
    narrower than that holds the robot at its mouth until its leg times out)."""
    max_edge_m: float = 6.0
    """Longest edge (the hand-made graphs' median edges are 3 to 6 m; a relocalizing robot
    looks for nodes 6 to 12 m away)."""
    tolerance_m: float = 0.25
    """An edge stays within this of the skeleton branch it replaces."""
    spur_m: float = 0.75
    """A dead end reaching less than this beyond its junction's clearance is pruned."""
    cover_radius_m: float = 1.5
    """Free space farther than this from every edge gets extra nodes."""
    cover_spacing_m: float = 3.0
    """Lattice spacing of the extra nodes (twice ``cover_radius_m``: a square lattice's
    edges then pass within ``cover_radius_m`` of every point between them)."""
    merge_m: float = 0.75
    """Nodes joined by an edge shorter than this become one, where the edges stay clear."""
    fill_clearance_m: float = 0.75
    """Extra nodes go where the walls are at least this far, where there is such a place."""
    door_clearance_m: float = 0.6
    """Edges with less clearance than this pass a doorway: ``has_door`` and ``door_speed_mps``."""
    door_speed_mps: float = 0.5
    """Speed limit of door edges (as in the shipped hand-made graphs)."""

    def __post_init__(self) -> None:
        require_positive(self, "graph.", "margin_m", "max_edge_m", "tolerance_m", "spur_m", "cover_radius_m",
                         "cover_spacing_m", "merge_m", "fill_clearance_m", "door_clearance_m", "door_speed_mps")

    @property
    def clearance_m(self) -> float:
        """The clearance every edge keeps from every wall."""
        return self.free_space.robot_radius_m + self.margin_m

    def key(self) -> str:
        """A stable text of the settings (part of the cache key)."""
        return json.dumps(asdict(self), sort_keys=True)
