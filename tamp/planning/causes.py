"""Why a problem was not solved, in words a user understands.

One classification for `tamp plan`, `tamp demo` and the rows of `tamp evaluate` (which store the
inputs, so the report recomputes the causes from the rows). In order of precedence:

- ``model_miss``: a step landed `MISS` (2 cm) or more from where the Dynamics Model predicted it, from
  the state the world was in before it: the model did not know this step (which, by how much).
- ``aimed_near_tolerance``: no step missed, but the plan taken was predicted `AIMED` (2 cm) or more
  from the goal: small errors were enough to end beyond the 5 cm tolerance.
- ``small_errors``: neither: errors under 2 cm per step added up.
- ``search_budget``: no plan: the continuous search reached its node or time limit, or stalled.
- ``pruned``: no plan: the search expanded every state its actions reach (goal-oriented pruning,
  plan depth) without a goal state.
- ``kinematics``: no plan: the plans and successors found were rejected by the kinematic check or
  failed refinement, or the search reached goal states only by actions the check rejects.
- ``no_symbolic_plan``: no plan from a symbolic planner alone (no learned operator sequence reaches
  the goal's symbols in the domains it planned in).
- ``empty_plan``: the planner returned no action while a block was off its goal.
- ``execution``: an action of the plan could not be carried out at execution (IK, motion or grasp).
- ``out_of_rounds``: a closed loop used up its rounds (the paper's k - 1) or its action budget.

A closed loop that stopped because a round found no plan gets that round's no-plan cause; one that
ran the paper's k - 1 rounds and executed its last plan to the end gets the cause of that plan's
miss (model miss, aim or small errors), as an open-loop plan does.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING, Sequence

from tamp.planning.search import SearchStatus, goal_states
from tamp.planning.vocabulary import LoopStop, Outcome

if TYPE_CHECKING:
    from tamp.planning.results import PlanResult

MISS = 0.02  # metres: a step whose worst block landed this far from the prediction is a model miss
AIMED = 0.02  # metres: a plan predicted this far from the goal was aimed near the 5 cm tolerance


class Cause(StrEnum):
    MODEL_MISS = "model_miss"
    AIMED_NEAR_TOLERANCE = "aimed_near_tolerance"
    SMALL_ERRORS = "small_errors"
    SEARCH_BUDGET = "search_budget"
    PRUNED = "pruned"
    KINEMATICS = "kinematics"
    NO_SYMBOLIC_PLAN = "no_symbolic_plan"
    EMPTY_PLAN = "empty_plan"
    EXECUTION = "execution"
    OUT_OF_ROUNDS = "out_of_rounds"


@dataclass(frozen=True)
class Failure:
    """What a failed run ended with: the inputs of `failure_cause`, as stored in an evaluation row."""

    outcome: str  # tamp.planning.vocabulary.Outcome value
    step_miss_m: Sequence[float] = ()  # per executed action: the worst block's distance from its prediction
    predicted_error_m: float | None = None  # the last plan taken: predicted distance to the goal
    loop: str | None = None  # closed loop: `ClosedLoopResult.stop` (a LoopStop value); None: open loop
    search: str | None = None  # the last planning call's continuous search status (None: it did not search)
    rejected: int = 0  # kinematic rejections of the last planning call (check and refinement)
    goals_rejected: int = 0  # goal states its search reached only by actions the kinematic check rejected
    refine_failure: dict | None = None  # the first action that could not be carried out (stage, where, reason)


def stop_record(loop: str | None, last: PlanResult | None) -> dict:
    """How a run ended, as a row stores it (`stop`): the closed loop's stop (None: open loop) and the last
    planning call's search status, kinematic rejections, goal states its search reached only by rejected
    actions, and predicted error."""
    rejected = sum(sum(c.values()) for c in last.rejected.values()) if last is not None and last.rejected else 0
    search = None if last is None else last.search
    return {"loop": loop, "search": None if search is None else str(search.status),
            "rejected": int(rejected), "goals_rejected": 0 if search is None else int(search.goals_rejected),
            "predicted_error_m": None if last is None or last.predicted_error is None else
            round(float(last.predicted_error), 6)}


def cause_of(outcome: str, step_miss_m: Sequence[float] | None, stop: dict | None,
             refine_failure: dict | None) -> tuple[Cause, str] | None:
    """`failure_cause` of what a row stores: its outcome, step misses, `stop_record` and refinement failure."""
    stop = stop or {}
    return failure_cause(Failure(outcome, step_miss_m or (), stop.get("predicted_error_m"), stop.get("loop"),
                                 stop.get("search"), stop.get("rejected") or 0, stop.get("goals_rejected") or 0,
                                 refine_failure))


def failure_cause(f: Failure) -> tuple[Cause, str] | None:
    """The cause of a failed run and a sentence that says it; None for a success."""
    if f.outcome == Outcome.SUCCESS:
        return None
    if f.loop == LoopStop.BUDGET:
        blocked = (f"; its last search reached {goal_states(f.goals_rejected)} only by actions the kinematic check "
                   f"rejects") if f.goals_rejected else ""
        return Cause.OUT_OF_ROUNDS, ("the closed loop used up its action or search budget without reaching the goal"
                                     + blocked)
    if f.outcome in (Outcome.KINEMATIC_FAILURE, Outcome.REFINEMENT_FAILURE) and f.refine_failure is not None:
        r = f.refine_failure
        return Cause.EXECUTION, (f"action {r.get('action')} could not be carried out at execution "
                                 f"({r.get('stage')}{', ' + r['where'] if r.get('where') else ''})")
    if f.outcome == Outcome.NO_PLAN or f.loop in (LoopStop.NO_PLAN, LoopStop.EMPTY_PLAN):
        return _no_plan(f)
    misses = list(f.step_miss_m or ())
    worst = max(range(len(misses)), key=lambda i: misses[i]) if misses else None
    if worst is not None and misses[worst] >= MISS:
        return Cause.MODEL_MISS, (f"step {worst + 1} landed {misses[worst] * 100:.1f} cm from the Dynamics "
                                  f"Model's prediction")
    if f.predicted_error_m is not None and f.predicted_error_m >= AIMED:
        return Cause.AIMED_NEAR_TOLERANCE, (f"the plan was predicted {f.predicted_error_m * 100:.1f} cm from the "
                                            f"goal; its steps landed within {MISS * 100:g} cm of their predictions")
    if f.loop == LoopStop.ROUNDS:
        return Cause.OUT_OF_ROUNDS, "the closed loop used up its replanning rounds"
    return Cause.SMALL_ERRORS, f"every step landed within {MISS * 100:g} cm of its prediction; the errors added up"


def _no_plan(f: Failure) -> tuple[Cause, str]:
    after = " (after executed actions)" if f.loop is not None and f.step_miss_m else ""
    if f.loop == LoopStop.EMPTY_PLAN:
        return Cause.EMPTY_PLAN, "the planner returned no action while a block was off its goal" + after
    if f.goals_rejected and f.search != SearchStatus.REFINEMENT_BUDGET:
        return Cause.KINEMATICS, (f"the continuous search reached {goal_states(f.goals_rejected)} only by actions "
                                  f"the kinematic check rejects{after}")
    if f.search in (SearchStatus.NODE_LIMIT, SearchStatus.TIME_LIMIT):
        return Cause.SEARCH_BUDGET, f"the continuous search reached its {f.search.replace('_', ' ')}{after}"
    if f.search == SearchStatus.STALLED:
        return Cause.SEARCH_BUDGET, f"the continuous search stopped coming closer to the goal{after}"
    if f.search is None and f.loop is None:
        return Cause.NO_SYMBOLIC_PLAN, "no symbolic plan reaches the goal's symbols"
    if f.search == SearchStatus.REFINEMENT_BUDGET or f.rejected:
        return Cause.KINEMATICS, ("every plan or successor found was rejected by the kinematic check or failed "
                                  f"refinement ({f.rejected} rejections){after}")
    return Cause.PRUNED, f"the search ran out of actions to try (pruning, plan depth){after}"


__all__ = ["AIMED", "MISS", "Cause", "Failure", "cause_of", "failure_cause", "stop_record"]
