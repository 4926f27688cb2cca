"""Level 2 of Algorithm 1 (line 16): the continuous search, with kinematics in its loop when given."""
from __future__ import annotations

import time
from dataclasses import replace
from typing import Sequence

from tamp.planning.config import PlanConfig
from tamp.planning.feasibility import Feasibility
from tamp.planning.models import Models
from tamp.planning.results import PlanResult, take_plan
from tamp.planning.search import SearchStatus, continuous_search


def level2(models: Models, X_init, X_goal, cfg: PlanConfig, result: PlanResult,
            feas: Feasibility | None = None) -> PlanResult:
    """Continuous search; with `feas`, infeasible successors are pruned and a found plan is refined,
    searching again without the failing (state, action) while the refinement budget lasts."""
    t = time.perf_counter()
    refine_before = result.timings.get("refine", 0.0)
    search_cfg = replace(cfg.search, eps=cfg.verify.eps)
    check = None if feas is None else feas.action
    graspable = None if feas is None else feas.kinematics.graspable(X_init)
    while True:
        out = continuous_search(models.require_dynamics(), X_init, X_goal, search_cfg, check,
                                frozenset() if feas is None else feas.pruned, started=result.started,
                                graspable=graspable)
        if feas is not None:
            feas.rejected[2].update(out.rejected)
            if result.search is not None:  # a search again after a refinement failure: count all
                for name in ("expanded", "generated", "duplicates", "predict_calls", "ungraspable"):
                    setattr(out, name, getattr(out, name) + getattr(result.search, name))
        result.search = out
        if not out.solved or feas is None or not out.plan:
            break
        if out_of_time(cfg, result):
            result.reasons.append(f"level 2: time limit ({cfg.search.time_limit:g} s) reached; the plan found was "
                                  "not refined")
            result.search.status, result.search.reason = SearchStatus.TIME_LIMIT, "time limit reached before refinement"
            break
        if feas.refinements_left <= 0:
            result.reasons.append(f"level 2: refinement budget ({cfg.kinematics.max_refinements}) used up; the plan "
                                  "found was not refined")
            result.search.status = SearchStatus.REFINEMENT_BUDGET
            result.search.reason = "refinement budget used up"
            break
        assert out.trajectory is not None  # a solved search has its predicted trajectory
        outcome = feas.refine(2, out.trajectory, out.plan)
        if outcome.success:
            break
        result.reasons.append(f"level 2: the plan found did not refine (action {outcome.action_index}: "
                              f"{outcome.message}); searching again without that (state, action)")
    # search time: the searches with their checks, not the refinements between them
    result.timings["search"] = time.perf_counter() - t - (result.timings.get("refine", 0.0) - refine_before)
    if out.solved:
        assert out.plan is not None and out.trajectory is not None  # solved: both set
        return take_plan(result, out.plan, 2, out.trajectory, X_goal)
    result.reasons.append(f"level 2: {out.reason}")
    return result


def out_of_time(cfg: PlanConfig, result: PlanResult) -> bool:
    """Whether the planning call of `result` has run past cfg.search.time_limit (never, when it is None)."""
    limit = cfg.search.time_limit
    return limit is not None and time.perf_counter() - result.started > limit


__all__: Sequence[str] = ["level2", "out_of_time"]
