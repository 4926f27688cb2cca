"""The bilevel planner (paper, Algorithm 1): a verified plan of Level 1, else Level 2's continuous search.

    result = plan_bilevel(models, X_init, X_goal, PlanConfig())

- `plan_bilevel` (method ``bilevel``): Level 1 (`tamp.planning.level1`): Sigma_init, Sigma_goal from
  the Symbolic Model -> probabilistic symbolic planning over N sampled domains -> verify candidates
  in decreasing frequency, return the first verified one. Level 2 (`tamp.planning.level2`, no
  verified candidate): continuous search. With our extensions (`Level1Config`, docs/beyond-the-paper.md).
- `plan_bilevel_alg1` (``bilevel_alg1``): the paper's Algorithm 1 exactly, `bilevel` with the extensions off.

Each stage returns its own result (`Level1Result`, `Level2Result`, the kinematic check's record) and
times itself on the call's `Clock`; the `PlanResult` is assembled from them at the end. The other
methods and the registry are in `tamp.planning.planners`, the closed loops in `tamp.planning.closed_loop`,
the configuration in `tamp.planning.config`.
"""
from __future__ import annotations

import time
from dataclasses import replace
from typing import AbstractSet, Sequence

import numpy as np

from tamp.planning.config import PlanConfig, paper_config
from tamp.planning.kinematic_check import Feasibility
from tamp.planning.level1 import level1, level1_serial
from tamp.planning.level2 import level2
from tamp.planning.models import Models
from tamp.planning.results import Clock, Level1Result, Level2Result, PlanResult, assemble
from tamp.planning.search import SearchConfig
from tamp.planning.verify import Verification, VerifyConfig, doubt
from tamp.planning.vocabulary import KinematicFeasibility


def plan_bilevel(models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
                 kinematics: KinematicFeasibility | None = None,
                 avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> PlanResult:
    """Algorithm 1 of the paper: a verified plan of Level 1, else Level 2's continuous search.

    With `kinematics` (and cfg.kinematics.feasibility) a verified plan must also pass the kinematic check on its
    predicted states and refine, else the next one is tried; Level 2 then prunes infeasible
    successors and the (state, action) pairs that failed refinement, and those of `avoid`
    ((`search.state_key`, action) pairs a closed loop came back from)."""
    started, clock = time.perf_counter(), Clock()
    feas = Feasibility.of(kinematics, cfg.kinematics, clock, cfg.search.resolution, avoid)
    first = level1(models, X_init, X_goal, cfg.level1, cfg.verify, clock, feas, cfg.search.release_targets)
    if first.chosen is None and cfg.level1.serial and cfg.level1.focused(len(X_init)):
        level1_serial(models, X_init, X_goal, cfg.level1, cfg.verify, clock, feas, first,  # our extension
                      cfg.search.release_targets)
    chosen = first.chosen
    waits = None if chosen is None else level1_waits(models, X_init, X_goal, chosen, cfg.level1.wait_beyond,
                                                     cfg.search, cfg.verify)
    second: Level2Result | None = None
    if chosen is None or waits is not None:  # line 16: continuous search fallback
        second = level2(models.require_dynamics(), X_init, X_goal, cfg.search, cfg.verify, clock, started, feas)
    plan: tuple[Sequence, int, np.ndarray] | None = None if second is None else second.plan
    reasons = [] if waits is None else [waits]
    if plan is None and chosen is not None and refined_late(first, feas, reasons):
        plan = (chosen.actions, 1, chosen.trajectory)
    return assemble("bilevel", X_goal, clock, started, level1=first, level2=second, reasons=reasons, plan=plan,
                    rejected=None if feas is None else feas.rejected,
                    refinements=() if feas is None else feas.refinements)


def refined_late(first: Level1Result, feas: Feasibility | None, reasons: list[str]) -> bool:
    """Whether Level 1's chosen plan may be returned when Level 2 has none: refined now if it waited unrefined
    (`Level1Result.refine_later`; why not into `reasons`)."""
    if not first.refine_later:
        return True
    assert feas is not None and first.chosen is not None  # refine_later: chosen after feas's check
    if feas.refinements_left <= 0:
        reasons.append(f"level 1: refinement budget ({feas.config.max_refinements}) used up; its waiting plan "
                       "was not refined")
        return False
    outcome = feas.refine(1, first.chosen.trajectory, first.chosen.actions)
    if not outcome.success:
        reasons.append(f"level 1: its waiting plan did not refine (action {outcome.action_index}: {outcome.message})")
    return outcome.success


def level1_waits(models: Models, X_init, X_goal, chosen: Verification, wait_beyond: float | None,
                 search: SearchConfig, goal: VerifyConfig) -> str | None:
    """Why Level 1's verified plan waits while Level 2 searches (our extensions; None: it is taken): predicted
    `wait_beyond` metres or more from the goal (`Level1Config.wait_beyond`; None: never, as in the paper) or
    doubtful (a step's 95 % bound, `verify.doubt`)."""
    if wait_beyond is not None and chosen.error >= wait_beyond:
        return (f"level 1: its verified plan is predicted {chosen.error * 100:.1f} cm from the goal "
                f"(over {wait_beyond * 100:g} cm); kept while level 2 searches")
    model = models.require_dynamics()
    if search.max_doubt is not None and doubt(model, chosen.trajectory, chosen.actions) > search.max_doubt:
        return (f"level 1: a step of its verified plan may miss by over {search.max_doubt * 100:g} cm (the Dynamics "
                "Model's 95 % bound); kept while level 2 searches")
    return None


def plan_bilevel_alg1(models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
                      kinematics: KinematicFeasibility | None = None) -> PlanResult:
    """The paper's Algorithm 1 exactly (the `paper` preset over `cfg`): ranked symbolic plans verified in order (any
    block picked) and the empty plan allowed whenever Sigma_init = Sigma_goal; its
    Level 2 returns the continuous search's first goal state, prunes actions by the paper's rule, counts h in metres
    and runs to its node budget (no stall cut), on the 1 cm duplicate grid its reproduction was measured with."""
    return replace(plan_bilevel(models, X_init, X_goal, paper_config(cfg)), method="bilevel_alg1")


__all__: Sequence[str] = ["level1_waits", "plan_bilevel", "plan_bilevel_alg1", "refined_late"]
