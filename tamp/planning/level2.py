"""Level 2 of Algorithm 1 (line 16): the continuous search, with kinematics in its loop when given."""
from __future__ import annotations

import time
from typing import Sequence

import numpy as np

from tamp.planning.kinematic_check import Feasibility
from tamp.planning.results import Clock, Level2Result
from tamp.planning.search import SearchConfig, SearchStatus, continuous_search
from tamp.planning.verify import DynamicsModel, VerifyConfig


def level2(model: DynamicsModel, X_init: np.ndarray, X_goal: np.ndarray, config: SearchConfig, goal: VerifyConfig,
           clock: Clock, started: float, feas: Feasibility | None = None, every_action: bool = False) -> Level2Result:
    """Continuous search; with `feas`, infeasible successors are pruned and a found plan is refined,
    searching again without the failing (state, action) while the refinement budget lasts. `started`:
    time.perf_counter() when the planning call began (`SearchConfig.time_limit` counts from it);
    `every_action`: over all actions (`continuous_search`)."""
    result = Level2Result()
    check = None if feas is None else feas.action
    graspable = None if feas is None else feas.kinematics.graspable(X_init)
    with clock.stage("search"):
        while True:
            out = continuous_search(model, X_init, X_goal, config, goal, feasible=check,
                                    pruned=frozenset() if feas is None else feas.pruned, started=started,
                                    graspable=graspable, every_action=every_action)
            if feas is not None:
                feas.rejected[2].update(out.rejected)
                if result.search is not None:  # a search again after a refinement failure: count all
                    for name in ("expanded", "generated", "duplicates", "predict_calls", "ungraspable"):
                        setattr(out, name, getattr(out, name) + getattr(result.search, name))
            result.search = out
            if not out.solved or feas is None or not out.plan:
                break
            if out_of_time(config.time_limit, started):
                result.reasons.append(f"level 2: time limit ({config.time_limit:g} s) reached; the plan found was "
                                      "not refined")
                out.status, out.reason = SearchStatus.TIME_LIMIT, "time limit reached before refinement"
                break
            if feas.refinements_left <= 0:
                result.reasons.append(f"level 2: refinement budget ({feas.config.max_refinements}) used up; the "
                                      "plan found was not refined")
                out.status, out.reason = SearchStatus.REFINEMENT_BUDGET, "refinement budget used up"
                break
            assert out.trajectory is not None  # a solved search has its predicted trajectory
            outcome = feas.refine(2, out.trajectory, out.plan)
            if outcome.success:
                break
            result.reasons.append(f"level 2: the plan found did not refine (action {outcome.action_index}: "
                                  f"{outcome.message}); searching again without that (state, action)")
    if not out.solved:
        result.reasons.append(f"level 2: {out.reason}")
    return result


def out_of_time(time_limit: float | None, started: float) -> bool:
    """Whether a planning call begun at `started` (time.perf_counter()) has run past `time_limit` seconds
    (never, when it is None)."""
    return time_limit is not None and time.perf_counter() - started > time_limit


__all__: Sequence[str] = ["level2", "out_of_time"]
