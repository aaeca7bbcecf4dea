"""The robot stack: one object, one step a frame (:mod:`autonomy.stack.robot`), what
each step returns (:mod:`autonomy.stack.output`), its configuration
(:mod:`autonomy.stack.config`) and its parts."""

from autonomy.stack.config import LOCALIZATION_GRID, LocalizationConfig, RecoveryConfig, StackConfig
from autonomy.stack.lost_view import SEEN_KEEP_S
from autonomy.stack.output import PlanView, StackOutput
from autonomy.stack.robot import RobotStack
from autonomy.stack.search_motion import most_open_way
from autonomy.stack.state import Perception

__all__ = [
    "LOCALIZATION_GRID",
    "SEEN_KEEP_S",
    "LocalizationConfig",
    "Perception",
    "PlanView",
    "RecoveryConfig",
    "RobotStack",
    "StackConfig",
    "StackOutput",
    "most_open_way",
]
