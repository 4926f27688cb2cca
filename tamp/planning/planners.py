"""The planning methods behind one interface (`METHODS`, same signature, same `PlanResult`) and `plan`.

    result = plan("bilevel", models, X_init, X_goal, PlanConfig())

- ``bilevel``        Algorithm 1 with our extensions (`tamp.planning.bilevel.plan_bilevel`).
- ``bilevel_alg1``   the paper's Algorithm 1 exactly (`plan_bilevel_alg1`).
- ``probabilistic``  the most frequent plan of the probabilistic symbolic planner, not verified
                     (its verification error is reported).
- ``deterministic``  the plan in the most-frequent-effect domain (baseline), not verified.
- ``cfs``            continuous forward search alone.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import AbstractSet, Callable, Sequence

from tamp.planning.bilevel import plan_bilevel, plan_bilevel_alg1
from tamp.planning.config import PlanConfig
from tamp.planning.kinematic_check import Feasibility
from tamp.planning.level1 import symbolic_plans, verify_candidate
from tamp.planning.level2 import level2
from tamp.planning.models import Models
from tamp.planning.results import Clock, Level1Result, PlanResult, assemble
from tamp.planning.validate import check_problem
from tamp.planning.verify import states_pair
from tamp.planning.vocabulary import KinematicFeasibility


def _symbolic_only(method: str, probabilistic: bool):
    def run(models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
            kinematics: KinematicFeasibility | None = None) -> PlanResult:
        started, clock, record = time.perf_counter(), Clock(), Level1Result()
        record.candidates = symbolic_plans(models, X_init, X_goal, cfg.level1, cfg.verify, clock, record, probabilistic)
        if not record.candidates:
            return assemble(method, X_goal, clock, started, level1=record)
        with clock.stage("verify"):
            v = verify_candidate(models, X_init, X_goal, record.candidates[0], cfg.verify)  # reported, not used
        return assemble(method, X_goal, clock, started, level1=record, plan=(v.actions, 1, v.trajectory))
    run.__doc__ = f"The {method} symbolic planner alone (top plan, unverified; `kinematics` is ignored)."
    return run


plan_probabilistic = _symbolic_only("probabilistic", True)
plan_deterministic = _symbolic_only("deterministic", False)


def plan_cfs(models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
             kinematics: KinematicFeasibility | None = None,
             avoid: AbstractSet[tuple[bytes, tuple]] = frozenset(), every_action: bool = False) -> PlanResult:
    """Continuous forward search alone; with `kinematics` (and cfg.kinematics.feasibility) infeasible successors
    are pruned, as are the pairs of `avoid` (see `plan_bilevel`), and the plan is refined before it is
    returned. `every_action`: over all 9 n^2 actions, not the goal-oriented ones (a closed loop's widened search)."""
    started, clock = time.perf_counter(), Clock()
    feas = Feasibility.of(kinematics, cfg.kinematics, clock, cfg.search.resolution, avoid)
    found = level2(models.require_dynamics(), X_init, X_goal, cfg.search, cfg.verify, clock, started, feas,
                   every_action)
    return assemble("cfs", X_goal, clock, started, level2=found, plan=found.plan,
                    rejected=None if feas is None else feas.rejected,
                    refinements=() if feas is None else feas.refinements)


@dataclass(frozen=True)
class Planner:
    """A planning method and what it can do."""

    run: Callable[..., PlanResult]  # (models, X_init, X_goal, cfg, kinematics=None[, avoid]) -> PlanResult
    kinematic: bool = False  # puts a kinematic checker it is given in its planning loop (cfg.kinematics.feasibility)
    keeps_plans: bool = False  # its closed loop keeps a plan on course (cfg.loop.keep_plan); else it replans each round


METHODS: dict[str, Planner] = {
    "bilevel": Planner(plan_bilevel, kinematic=True, keeps_plans=True),
    "bilevel_alg1": Planner(plan_bilevel_alg1),
    "probabilistic": Planner(plan_probabilistic),
    "deterministic": Planner(plan_deterministic),
    "cfs": Planner(plan_cfs, kinematic=True, keeps_plans=True),
}


def plan(method: str, models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
         kinematics: KinematicFeasibility | None = None,
         avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> PlanResult:
    """Run one of METHODS on (X_init, X_goal), both (n, 5) arrays. `kinematics` (e.g. a
    tamp.sim.kinematic_checker.FeasibilityChecker that observed the scene of X_init) puts kinematic feasibility
    into the planning loop of the `kinematic` ones (unless cfg.kinematics.feasibility is False); with it, those
    methods also leave out the (state key, action) pairs of `avoid` (a closed loop's revisits)."""
    if method not in METHODS:
        raise ValueError(f"unknown planning method {method!r}; choose one of {', '.join(METHODS)}")
    X_init, X_goal = states_pair(X_init, X_goal)
    # an observed X_init may hold tilted blocks: checked as any scene, not as one placed upright
    check_problem(X_init, X_goal, where="plan()", n_max=getattr(models, "n_max", None), init_upright=False)
    extra = {"avoid": avoid} if avoid and METHODS[method].kinematic else {}
    return METHODS[method].run(models, X_init, X_goal, cfg, kinematics=kinematics, **extra)


__all__: Sequence[str] = ["METHODS", "Planner", "plan", "plan_cfs",
                          "plan_deterministic", "plan_probabilistic"]
