"""Small configuration structs of the planner that several planning modules share.

`PlanConfig` (tamp.planning.bilevel) composes them; each says what one concern does and why its
defaults.
"""
from __future__ import annotations

from dataclasses import dataclass

from tamp.errors import UserError


@dataclass(frozen=True)
class LoopConfig:
    """The closed loop that does not know k (`tamp.planning.closed_loop.plan_until_goal`)."""

    max_actions: int = 12  # actions sent to the world before the loop gives up: a goal of k <= 5 random
    #   actions needs at most 5, the rest is room to recover from misses and to make room
    widen: bool = True  # a round without a plan searches again over all 9 n^2 actions (moves that make room,
    #   unstack, move blocks already at their goal), not only the goal-oriented ones
    widen_expansions: int = 400  # node budget of the widened search (about 2-4 s at 4 blocks with kinematics)
    search_budget: int = 3000  # continuous-search expansions over all rounds: twice one search's default budget,
    #   so that a loop whose rounds keep failing ends in about the time of two failed searches
    progress: float = 0.02  # metres (summed over blocks): without a plan, the loop takes a step toward the closest
    #   state its widened search reached only if that is at least this much closer to the goal
    revisit: float = 0.01  # metres: back within this of an earlier observed state (every block), the loop leaves
    #   out the actions it took from there: in a deterministic world they would start the same cycle again

    def __post_init__(self) -> None:
        if not self.revisit >= 0 or not self.progress >= 0:
            raise UserError(f"LoopConfig.revisit and .progress must be distances of 0 m or more, got {self.revisit} "
                            f"and {self.progress}")
        if self.max_actions < 1 or self.widen_expansions < 1 or self.search_budget < 1:
            raise UserError(f"the closed loop needs at least 1 action and 1 expansion of its searches, got "
                            f"{self.max_actions} actions, {self.widen_expansions} expansions widened and a search "
                            f"budget of {self.search_budget}")
