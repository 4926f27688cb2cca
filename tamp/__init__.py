"""TAMP for a UR10e: the Drake block world, skills, motion, execution and the bilevel planner."""
from tamp.structs import PickPlace, StepInfo, WorldConfig
from tamp.world import World

__all__ = ["World", "WorldConfig", "PickPlace", "StepInfo"]
