"""Kinematics in the planning loop: the check and full refinement of one planning call (`Feasibility`).

The planner sees the kinematics only through `tamp.planning.vocabulary.KinematicFeasibility` (Drake's
checker in `tamp.sim.kinematic_checker`), so this module imports no Drake.
"""
from __future__ import annotations

from collections import Counter
from typing import AbstractSet, Sequence

import numpy as np

from tamp.planning.config import KinematicsConfig
from tamp.planning.results import Clock
from tamp.planning.search import state_key
from tamp.planning.verify import Verification
from tamp.planning.vocabulary import Infeasible, KinematicFeasibility, RefinementOutcome


class Feasibility:
    """The kinematic check and refinement of one planning call, and its record: results cached per (state,
    action), rejections counted per level and reason (`rejected`), every full refinement (`refinements`),
    time on the call's clock ("feasibility", "refine") and the refinement budget.

    `resolution` (metres) is the grid of the (state, action) keys, the continuous search's (`state_key`), so
    that `avoid` and the pairs it prunes name the search's states."""

    def __init__(self, kinematics: KinematicFeasibility, config: KinematicsConfig, clock: Clock, resolution: float,
                 avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> None:
        self.kinematics, self.config, self.clock, self.resolution = kinematics, config, clock, resolution
        # (state key, action) known to fail: the closed loop's revisits (`avoid`), then failed refinements
        self.cache: dict[tuple[bytes, tuple], Infeasible | None] = {key: Infeasible.REVISIT for key in avoid}
        self.pruned: set[tuple[bytes, tuple]] = set(avoid)
        self.rejected: dict[int, Counter] = {1: Counter(), 2: Counter()}
        self.refinements: list[dict] = []  # level, plan, outcome of each full refinement
        for stage in ("feasibility", "refine"):
            clock.seconds.setdefault(stage, 0.0)

    @classmethod
    def of(cls, kinematics: KinematicFeasibility | None, config: KinematicsConfig, clock: Clock, resolution: float,
           avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> "Feasibility | None":
        """The feasibility of a planning call, or None when it is off (no kinematics, or
        config.feasibility False)."""
        return cls(kinematics, config, clock, resolution, avoid) if kinematics is not None and config.feasibility \
            else None

    def action(self, X: np.ndarray, action) -> Infeasible | None:
        """The check of one action in the predicted state X (cached)."""
        action = tuple(int(v) for v in action)
        key = (state_key(X, self.resolution), action)
        if key in self.pruned:
            return self.cache.get(key) or Infeasible.REFINE_MOTION
        if key not in self.cache:
            with self.clock.stage("feasibility"):
                self.cache[key] = self.kinematics.check(X, np.asarray([action], dtype=np.int64))[0]
        return self.cache[key]

    def plan(self, trajectory: np.ndarray, actions) -> Infeasible | None:
        """The first reason an action of the plan fails on its predicted state, or None."""
        for X, a in zip(trajectory, actions):
            reason = self.action(X, a)
            if reason is not None:
                return reason
        return None

    def verdicts(self, trajectory: np.ndarray, actions) -> tuple[str, ...]:
        """What the check and refinement found so far for each action of a plan on its predicted states: "ok", the
        reason it failed, or "unchecked" (nothing is checked here: the search record reads it)."""
        out = []
        for X, a in zip(trajectory, actions):
            key = (state_key(X, self.resolution), tuple(int(v) for v in a))
            out.append("unchecked" if key not in self.cache else "ok" if self.cache[key] is None
                       else str(self.cache[key]))
        return tuple(out)

    @property
    def refinements_left(self) -> int:
        return self.config.max_refinements - len(self.refinements)

    def refine(self, level: int, trajectory: np.ndarray, actions) -> RefinementOutcome:
        """Full refinement; a failure prunes its (predicted state, action) for the rest of the call."""
        with self.clock.stage("refine"):
            outcome = self.kinematics.refine([tuple(int(v) for v in a) for a in actions], trajectory, self.resolution)
        self.refinements.append({"level": level, "plan": [list(map(int, a)) for a in actions],
                                        "failed_action": outcome.action_index,
                                        "reason": None if outcome.reason is None else outcome.reason.value,
                                        "message": outcome.message, "actions": list(outcome.steps)})
        if not outcome.success:
            k = outcome.action_index
            key = (state_key(trajectory[k], self.resolution), tuple(int(v) for v in actions[k]))
            self.pruned.add(key)
            self.cache[key] = outcome.reason
            self.rejected[level][outcome.reason] += 1
        return outcome


def feasible_choice(verified: list[Verification], feas: Feasibility | None, refine: bool = True
                    ) -> Verification | None:
    """The first verified plan (smallest error first) that passes the kinematic check on its predicted
    states and then refines (`refine` False: the check alone, the caller refines it if it needs it); without
    `feas`, the first verified plan."""
    if feas is None:
        return verified[0] if verified else None
    for v in verified:
        reason = feas.plan(v.trajectory, v.actions)
        if reason is not None:
            feas.rejected[1][reason] += 1
            continue
        if not v.actions or not refine:
            return v
        if feas.refinements_left <= 0:
            return None
        if feas.refine(1, v.trajectory, v.actions).success:
            return v
    return None


__all__: Sequence[str] = ["Feasibility", "feasible_choice"]
