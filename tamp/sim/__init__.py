"""The simulated block world in Drake: `World` (the pick-place skill with IK, OMPL motions and
physics), refinement of plans into joint trajectories and their execution.

`tamp.sim.world_types` (the world's configuration and step record) is plain data; `World` is imported
on first use, so that reading a configuration loads no Drake.
"""
from typing import Any

from tamp.sim.world_types import StepInfo, WorldConfig

__all__ = ["World", "WorldConfig", "StepInfo"]


def __getattr__(name: str) -> Any:
    if name == "World":
        from tamp.sim.world import World

        return World
    raise AttributeError(f"module 'tamp.sim' has no attribute {name!r}")
