"""TAMP for a UR10e: the Drake block world, skills, motion, execution and the bilevel planner."""
import logging

import pydrake.common  # noqa: F401  (sets up the "drake" logger, which we then quieten)

logging.getLogger("drake").setLevel(logging.WARNING)  # keep Drake's INFO lines off the console

from tamp.structs import PickPlace, StepInfo, WorldConfig
from tamp.world import World

__all__ = ["World", "WorldConfig", "PickPlace", "StepInfo"]
