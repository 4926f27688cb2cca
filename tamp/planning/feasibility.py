"""Kinematics in the planning loop: the check and full refinement of one planning call (`Feasibility`).

The planner sees the kinematics only through `tamp.planning.structs.KinematicFeasibility` (Drake's
checker in `tamp.sim.feasibility`), so this module imports no Drake.
"""
from __future__ import annotations

import time
from collections import Counter
from typing import AbstractSet, Sequence

import numpy as np

from tamp.planning.config import PlanConfig
from tamp.planning.results import PlanResult
from tamp.planning.search import state_key
from tamp.planning.structs import Infeasible, KinematicFeasibility, RefinementOutcome
from tamp.planning.verify import Verification


class Feasibility:
    """The kinematic check and refinement of one planning call: results cached per (state, action),
    rejections counted per level and reason, time and refinement budget tracked."""

    def __init__(self, kinematics: KinematicFeasibility, cfg: PlanConfig, result: PlanResult,
                 avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> None:
        self.kinematics, self.cfg, self.result = kinematics, cfg, result
        self.resolution = cfg.search.resolution
        # (state key, action) known to fail: the closed loop's revisits (`avoid`), then failed refinements
        self.cache: dict[tuple[bytes, tuple], Infeasible | None] = {key: Infeasible.REVISIT for key in avoid}
        self.pruned: set[tuple[bytes, tuple]] = set(avoid)
        self.rejected: dict[int, Counter] = {1: Counter(), 2: Counter()}
        result.rejected = self.rejected
        result.timings.setdefault("feasibility", 0.0)
        result.timings.setdefault("refine", 0.0)

    @classmethod
    def of(cls, kinematics: KinematicFeasibility | None, cfg: PlanConfig, result: PlanResult,
           avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> "Feasibility | None":
        """The feasibility of a planning call, or None when it is off (no kinematics, or
        cfg.kinematics.feasibility False)."""
        return cls(kinematics, cfg, result, avoid) if kinematics is not None and cfg.kinematics.feasibility else None

    def action(self, X: np.ndarray, action) -> Infeasible | None:
        """The check of one action in the predicted state X (cached)."""
        action = tuple(int(v) for v in action)
        key = (state_key(X, self.resolution), action)
        if key in self.pruned:
            return self.cache.get(key) or Infeasible.REFINE_MOTION
        if key not in self.cache:
            t = time.perf_counter()
            self.cache[key] = self.kinematics.check(X, np.asarray([action], dtype=np.int64))[0]
            self.result.timings["feasibility"] += time.perf_counter() - t
        return self.cache[key]

    def plan(self, trajectory: np.ndarray, actions) -> Infeasible | None:
        """The first reason an action of the plan fails on its predicted state, or None."""
        for X, a in zip(trajectory, actions):
            reason = self.action(X, a)
            if reason is not None:
                return reason
        return None

    @property
    def refinements_left(self) -> int:
        return self.cfg.kinematics.max_refinements - len(self.result.refinements)

    def refine(self, level: int, trajectory: np.ndarray, actions) -> RefinementOutcome:
        """Full refinement; a failure prunes its (predicted state, action) for the rest of the call."""
        t = time.perf_counter()
        outcome = self.kinematics.refine([tuple(int(v) for v in a) for a in actions], trajectory)
        self.result.timings["refine"] += time.perf_counter() - t
        self.result.refinements.append({"level": level, "plan": [list(map(int, a)) for a in actions],
                                        "failed_action": outcome.action_index,
                                        "reason": None if outcome.reason is None else outcome.reason.value,
                                        "message": outcome.message})
        if not outcome.success:
            k = outcome.action_index
            key = (state_key(trajectory[k], self.resolution), tuple(int(v) for v in actions[k]))
            self.pruned.add(key)
            self.cache[key] = outcome.reason
            self.rejected[level][outcome.reason] += 1
        return outcome


def feasible_choice(verified: list[Verification], feas: Feasibility | None) -> Verification | None:
    """The first verified plan (smallest error first) that passes the kinematic check on its predicted
    states and then refines; without `feas`, the first verified plan."""
    if feas is None:
        return verified[0] if verified else None
    for v in verified:
        reason = feas.plan(v.trajectory, v.actions)
        if reason is not None:
            feas.rejected[1][reason] += 1
            continue
        if not v.actions:
            return v
        if feas.refinements_left <= 0:
            return None
        if feas.refine(1, v.trajectory, v.actions).success:
            return v
    return None


__all__: Sequence[str] = ["Feasibility", "feasible_choice"]
