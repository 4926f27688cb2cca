"""The bilevel planner (paper, Algorithm 1): a verified plan of Level 1, else Level 2's continuous search.

    result = plan_bilevel(models, X_init, X_goal, PlanConfig())

- `plan_bilevel` (method ``bilevel``): Level 1 (`tamp.planning.level1`): Sigma_init, Sigma_goal from
  the Symbolic Model -> probabilistic symbolic planning over N sampled domains -> verify candidates
  in decreasing frequency, return the first verified one. Level 2 (`tamp.planning.level2`, no
  verified candidate): continuous search. With our extensions (`Level1Config`, docs/beyond-the-paper.md).
- `plan_bilevel_alg1` (``bilevel_alg1``): the paper's Algorithm 1 exactly, `bilevel` with the extensions off.

The other methods and the registry are in `tamp.planning.methods`, the closed loops in
`tamp.planning.closed_loop`, the configuration in `tamp.planning.config`.
"""
from __future__ import annotations

from dataclasses import replace
from typing import AbstractSet, Sequence

from tamp.planning.config import PlanConfig
from tamp.planning.feasibility import Feasibility
from tamp.planning.level1 import level1, level1_serial
from tamp.planning.level2 import level2
from tamp.planning.models import Models
from tamp.planning.results import PlanResult, take_plan, timed
from tamp.planning.structs import KinematicFeasibility
from tamp.planning.verify import Verification, doubt, fragility


def plan_bilevel(models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
                 kinematics: KinematicFeasibility | None = None,
                 avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> PlanResult:
    """Algorithm 1 of the paper: a verified plan of Level 1, else Level 2's continuous search.

    With `kinematics` (and cfg.kinematics.feasibility) a verified plan must also pass the kinematic check on its
    predicted states and refine, else the next one is tried; Level 2 then prunes infeasible
    successors and the (state, action) pairs that failed refinement, and those of `avoid`
    ((`search.state_key`, action) pairs a closed loop came back from)."""
    def body(result: PlanResult) -> PlanResult:
        feas = Feasibility.of(kinematics, cfg, result, avoid)
        chosen = level1(models, X_init, X_goal, cfg, result, feas)
        if chosen is None and cfg.level1.serial and cfg.level1.focused(len(X_init)):
            chosen = level1_serial(models, X_init, X_goal, cfg, result, feas)  # our extension
        confident = cfg.level1.confident
        if chosen is not None and confident is not None and chosen.error >= confident:
            # our extension: verified, but predicted to miss the goal
            result.reasons.append(f"level 1: its verified plan is predicted {chosen.error * 100:.1f} cm from the "
                                  f"goal (over {confident * 100:g} cm); kept while level 2 searches")
        elif chosen is not None and confident is not None and _fragile(models, X_init, X_goal, chosen, cfg):
            result.reasons.append(f"level 1: its verified plan misses the goal in over {cfg.search.max_fragility:.0%} "
                                  "of its perturbed rollouts; kept while level 2 searches")
        elif chosen is not None and _doubtful(models, chosen, cfg):
            result.reasons.append(f"level 1: a step of its verified plan may miss by over "
                                  f"{(cfg.search.max_doubt or 0.0) * 100:g} cm (the Dynamics Model's 95 % bound); "
                                  "kept while level 2 searches")
        elif chosen is not None:
            return take_plan(result, chosen.actions, 1, chosen.trajectory, X_goal)
        result = level2(models, X_init, X_goal, cfg, result, feas)  # line 16: continuous search fallback
        if result.solved or chosen is None:
            return result
        return take_plan(result, chosen.actions, 1, chosen.trajectory, X_goal)
    return timed("bilevel", body)


def _fragile(models: Models, X_init, X_goal, chosen: Verification, cfg: PlanConfig) -> bool:
    """Whether more than cfg.search.max_fragility of the plan's perturbed rollouts miss the goal
    (`verify.fragility`; our extension, the continuous search's test of a goal state)."""
    limit = cfg.search.max_fragility
    return limit is not None and bool(chosen.actions) and fragility(
        models.require_dynamics(), X_init, X_goal, chosen.actions, cfg.verify.eps, cfg.search.noise) > limit


def _doubtful(models: Models, chosen: Verification, cfg: PlanConfig) -> bool:
    """Whether a step of the plan may miss by more than cfg.search.max_doubt (`verify.doubt`; our extension)."""
    limit = cfg.search.max_doubt
    return limit is not None and doubt(models.require_dynamics(), chosen.trajectory, chosen.actions) > limit


def plan_bilevel_alg1(models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
                      kinematics: KinematicFeasibility | None = None) -> PlanResult:
    """The paper's Algorithm 1 exactly: ranked symbolic plans verified alone (no look-alike
    alternatives, any block picked) and the empty plan allowed whenever Sigma_init = Sigma_goal; its
    Level 2 returns the continuous search's first goal state, prunes actions by the paper's rule, counts h in metres
    and runs to its node budget (no stall cut)."""
    paper = replace(cfg, level1=replace(cfg.level1, alternatives=0, nonempty=False, focus_from=None, confident=None,
                                        cut=False),
                    kinematics=replace(cfg.kinematics, feasibility=False),
                    search=replace(cfg.search, look_on=0, release_targets=False, max_fragility=None, max_doubt=None,
                                   stall=None, greedy_from=None))
    result = plan_bilevel(models, X_init, X_goal, paper)
    result.method = "bilevel_alg1"
    return result


__all__: Sequence[str] = ["plan_bilevel", "plan_bilevel_alg1"]
