"""Plain data of the planners, shared with the simulator: block types, actions, infeasibility.

`PickPlace` crosses package borders as a 4-tuple (learned/ and symbolic/ never import tamp), so it
is a NamedTuple. Lengths are metres, angles radians, times seconds.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import NamedTuple, Protocol, Sequence

import numpy as np

# Block types: index into the one-hot part of X.
SMALL, LARGE = 0, 1
TYPE_NAMES = ("small", "large")
# Box sizes along the block's own x, y, z (metres).
BLOCK_SIZES = {SMALL: (0.05, 0.05, 0.05), LARGE: (0.05, 0.25, 0.05)}
BLOCK_HEIGHT, = {size[2] for size in BLOCK_SIZES.values()}  # metres: both block types are this tall
ON_TABLE = 0.04  # metres: a block (or goal) whose centre is lower stands on the table
OFFSET_STEP = 0.075  # metres per unit of offset, along tamp.sim.skill.Scene.offset_axis_xy
OFFSETS = (-1, 0, 1)


class PickPlace(NamedTuple):
    """Pick object `pick` at `grasp_offset` and release it on object `place` at `release_offset`.

    Offsets are in {-1, 0, +1} and scale OFFSET_STEP along the object's offset axis (y signed toward +y).
    `place == pick` places the object where it was, shifted by the offsets.
    """

    pick: int
    grasp_offset: int
    place: int
    release_offset: int


def action_words(a) -> str:
    """A pick-place as the commands print it: "pick 0 at +0, place on 1 at -1"."""
    return f"pick {a[0]} at {a[1]:+d}, place on {a[2]} at {a[3]:+d}"


class Infeasible(StrEnum):
    """Why an action was found infeasible: by the cheap check on a predicted scene (the first three)
    or by full refinement (IK, motion planning, grasp, from tamp.sim.refine)."""

    NO_GRASP = "no_grasp"  # the grasp point does not lie on the picked block (jaws close on nothing or another)
    IK = "ik"  # a waypoint has no closed-form IK solution on the skill's branch
    COLLISION = "collision"  # a waypoint configuration collides with another block or the table
    REFINE_IK = "refine_ik"
    REFINE_MOTION = "refine_motion"
    REFINE_GRASP = "refine_grasp"
    REVISIT = "revisit"  # a closed loop took this action from this state before and came back to it


@dataclass(frozen=True)
class RefinementOutcome:
    """Result of fully refining a plan: None fields when every action refined."""

    action_index: int | None = None  # first action that failed
    reason: Infeasible | None = None
    message: str = ""
    steps: tuple[dict, ...] = ()  # per action refined or tried: "ik_branch", "planner" (per motion), "time_s",
    #   "failure" (None: it refined); the search record's

    @property
    def success(self) -> bool:
        return self.action_index is None


class KinematicFeasibility(Protocol):
    """What the planners need from the simulator side (tamp.sim.kinematic_checker.FeasibilityChecker): a cheap
    check of actions in a predicted scene and full refinement of a plan from the observed scene.
    The planner modules see only this protocol and so stay free of Drake."""

    def check(self, X: np.ndarray, actions: np.ndarray) -> list[Infeasible | None]:
        """Per action (B, 4) in the predicted scene X (n, 5): None if feasible, else why not."""

    def graspable(self, X: np.ndarray) -> np.ndarray:
        """(n, 3) bool per block of X and grasp offset (-1, 0, +1): False where `check` says NO_GRASP for every
        action of that pick and grasp, whatever the scene (the search leaves them out before predicting them)."""

    def refine(self, actions: Sequence[Sequence[int]], trajectory: np.ndarray | None = None,
               grid_m: float = ...) -> RefinementOutcome:
        """Fully refine the plan (IK, OMPL motions, grasps) from the observed scene, each action in
        the scene `trajectory` (the predicted states along the plan) gives before it; no physics. A failure
        is remembered for scenes the same on a `grid_m` grid (metres; the search's)."""


class Outcome(StrEnum):
    """What became of a problem once its plan was refined and executed (a row of `tamp evaluate`)."""

    SUCCESS = "success"  # every block within eps of its goal
    NO_PLAN = "no_plan"  # the planner returned no plan
    KINEMATIC_FAILURE = "kinematic_failure"  # an action of the plan had no IK solution
    REFINEMENT_FAILURE = "refinement_failure"  # no collision-free motion, or the grasp missed
    WRONG_PLAN = "wrong_plan"  # executed, but some block ended beyond eps of its goal
    ERROR = "error"  # planning or execution raised (an evaluation records it and goes on)

    @classmethod
    def of(cls, solved: bool, failure_stage: str | None, final_error: float, eps: float) -> "Outcome":
        """The outcome of a plan (`solved`) whose refinement failed at `failure_stage` ("ik", "motion",
        "grasp"; None if every action refined) and ended `final_error` metres from the goal."""
        if not solved:
            return cls.NO_PLAN
        if failure_stage is not None:
            return cls.KINEMATIC_FAILURE if failure_stage == "ik" else cls.REFINEMENT_FAILURE
        return cls.SUCCESS if final_error < eps else cls.WRONG_PLAN


class Loop(StrEnum):
    """The closed loops (`tamp.planning.closed_loop`)."""

    PAPER = "paper"  # the paper's replanning: k - 1 rounds, the last plan executed to its end (Table IV)
    UNTIL_GOAL = "goal"  # the loop that does not know k: plan again after every action until the goal


class LoopStop(StrEnum):
    """How a closed loop ended (`ClosedLoopResult.stop`)."""

    GOAL = "goal"  # the observed state is within eps of the goal
    NO_PLAN = "no_plan"  # a round found no plan
    EMPTY_PLAN = "empty_plan"  # a round's plan had no action
    ROUNDS = "rounds"  # the paper's loop ran its k - 1 rounds and executed its last plan
    BUDGET = "budget"  # the loop that does not know k used up its actions or search expansions


# the outcomes the statistics count (an ERROR row is listed apart)
OUTCOMES = tuple(o.value for o in Outcome if o is not Outcome.ERROR)
