"""The simulated block world in Drake: `World` (the pick-place skill with IK, OMPL motions and
physics), refinement of plans into joint trajectories and their execution."""
import logging

import pydrake.common  # noqa: F401  (sets up the "drake" logger, which we then quieten)

logging.getLogger("drake").setLevel(logging.WARNING)  # keep Drake's INFO lines off the console

from tamp.sim.structs import StepInfo, WorldConfig  # noqa: E402
from tamp.sim.world import World  # noqa: E402

__all__ = ["World", "WorldConfig", "StepInfo"]
