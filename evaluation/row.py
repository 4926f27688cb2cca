"""One row of `tamp evaluate`: a (problem, method) planned, refined and executed, as `Row` holds it.

`Row` is the schema: its fields, in order, are the keys of every line of rows.jsonl (`ROW_KEYS`);
the helpers below compute them from what the planners and the worlds return. A row that raised
(`Evaluator.error_row`) has the same keys, outcome "error", and two more: `error` and `traceback`.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any, Sequence

import numpy as np

from tamp.planning.causes import cause_of
from tamp.planning.results import LEVEL1_STAGES
from tamp.planning.steps import symbolic_steps
from tamp.planning.vocabulary import Outcome

ERROR_OUTCOME = Outcome.ERROR.value  # a pair that raised (see Evaluator.error_row); not one of OUTCOMES
MAX_CANDIDATES = 20  # candidates kept per row, in the planner's order


@dataclass(frozen=True)
class Row:
    """The fields of a row (metres, seconds; None where a method has no such thing)."""

    problem: str  # the problem's name in the set
    n: int  # blocks
    k: int | None  # random actions that made the goal
    run: int  # the problem set's run (`tamp problems --runs`)
    protocol: str | None  # "strict" or "paper"
    moved: int | None  # of the k actions, how many moved a block
    method: str
    solved: bool  # the planner returned a plan (closed loop: its first round did)
    level: int | None  # 1 (symbolic) or 2 (continuous search) gave the plan; closed loop: the first round's
    plan: list[list[int]] | None  # open loop: the plan executed (oracle: the last one); closed loop: the actions sent
    planning_time_s: float  # closed loop: summed over rounds
    level1_time_s: float | None  # Level 1's stages (symbols, symbolic, verify), summed over rounds
    predicted_error_m: float | None  # the plan's predicted distance to the goal (closed loop: the first round's)
    candidates: list[dict]  # the planner's candidates in its order: the ranked symbolic plans
    refined: bool | None  # every action refined (IK, collision-free motion, grasp)
    refine_failure: dict | None  # the first action that did not refine: stage, where, reason
    refine_time_s: list[float]  # per World.step (planning and, in `full`, execution)
    executed_actions: int
    # probabilistic_oracle: ranked plans executed from X_init, most frequent first, until one succeeds or
    #   `EvalConfig.oracle_max_plans` (`plan` and the refinement fields are the last one's)
    executed_plans: int | None
    final_error_m: float | None  # the world's final state: the largest distance of a block to its goal
    success: bool
    outcome: str  # an Outcome value (`row_outcome`); `bilevel_loop` rows are judged by where the loop ended
    rounds: int | None  # closed loop: the replanning rounds (planning calls - 1)
    fidelity: str  # the world that executed: "fast" or "full"
    eps_m: float  # the success tolerance
    tau_verify_m: float
    symbolic_backend: str | None  # None: a method without a symbolic level
    feasibility: dict | None  # kinematics in the planning loop: rejections by level and reason, refinements
    search_time_s: float | None  # the continuous search's own time (not its kinematic check, not refinement)
    feasibility_time_s: float | None  # the kinematic check (Level 1's plans, Level 2's successors)
    plan_refine_time_s: float | None  # the full refinements the planner ran before returning a plan
    level1_stages_s: dict | None  # seconds per Level-1 stage, summed over rounds
    search_expanded: int | None  # continuous-search expansions, summed over rounds
    # per executed action, the Dynamics Model's position error (mean over blocks) predicting its effect from the
    #   state the world was in before it: how well the model knows the actions the method chose
    effect_error_m: list[float | None] | None
    step_miss_m: list[float | None] | None  # the same with the worst block: how far it landed from its prediction
    # how the run ended: the closed loop's `LoopStop` (None: open loop), the last planning call's search status,
    #   kinematic rejections, goal states its search reached only by rejected actions (`goals_rejected`) and predicted
    #   error (`tamp.planning.causes.stop_record`); faults injected; the misses
    #   the loop that does not know k remembered (`remembered`, `tamp.planning.experience`)
    stop: dict | None
    cause: list[str] | None  # [cause, sentence] of a failed row (`row_cause`, recomputed from these fields)
    # per step executed or attempted, the step through the learned abstraction (`tamp.planning.steps`): operator,
    #   probability, on_plan, kinematic ("ok" or the check's reason), refined, match, mismatched_bits, allowed,
    #   error_m; closed loop: the round and whether its plan was planned or kept. None without a Symbolic Model
    steps: list[dict] | None
    # per executed action, the prediction against the world (`tamp.planning.calibration`): class, miss, the 95 %
    #   bound of that miss and its two parts. None without a Dynamics Model
    predictions: list[dict] | None
    transitions: list[dict] | None  # per executed action: X, action, X', the block carried, the world's status

    def __post_init__(self) -> None:
        if self.outcome not in {o.value for o in Outcome}:
            raise ValueError(f"a row's outcome must be an Outcome, got {self.outcome!r}")

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of rows.jsonl, keys in `ROW_KEYS` order."""
        return asdict(self)


ROW_KEYS = tuple(f.name for f in fields(Row))
# the only fields that vary between runs
TIMING_KEYS = ("planning_time_s", "level1_time_s", "refine_time_s", "search_time_s", "feasibility_time_s",
               "plan_refine_time_s", "level1_stages_s")


def row_outcome(solved: bool, refine_failure: dict | None, final_error: float, eps: float) -> Outcome:
    """The row's Outcome (see `tamp.planning.vocabulary.Outcome`)."""
    return Outcome.of(solved, None if refine_failure is None else refine_failure["stage"], final_error, eps)


def round_m(x: float | None, digits: int = 6) -> float | None:
    return None if x is None else round(float(x), digits)


def as_lists(plan) -> list[list[int]] | None:
    return None if plan is None else [[int(v) for v in a] for a in plan]


def level1_time(result) -> float:
    return sum(result.timings.get(k, 0.0) for k in LEVEL1_STAGES)


def level1_stages(results: list) -> dict[str, float | None] | None:
    """Seconds per Level-1 stage (symbols, symbolic, verify), summed over planning calls; None without
    a symbolic level."""
    if not any("symbols" in r.timings for r in results):
        return None
    return {k: round_m(sum(r.timings.get(k, 0.0) for r in results)) for k in LEVEL1_STAGES}


def search_expanded(results: list) -> int | None:
    """Continuous-search expansions summed over planning calls; None when no call searched."""
    searched = [r.search.expanded for r in results if r.search is not None]
    return sum(searched) if searched else None


def candidate_records(result) -> list[dict]:
    return [{"error_m": round_m(c.error), "verified": None if c.verified is None else bool(c.verified),
             "count": int(c.count)}
            for c in result.candidates[:MAX_CANDIDATES]]


def feasibility_fields(results: list) -> dict:
    """Row fields of kinematics in the planning loop, summed over planning calls (closed loop: rounds):
    rejections per level and reason, refinements tried and failed, check, search and refinement time."""
    used = [r for r in results if r.rejected is not None]
    fields: dict[str, Any]
    fields = {"feasibility": None, "search_time_s": round_m(sum(r.timings.get("search", 0.0) for r in results)),
              "feasibility_time_s": None, "plan_refine_time_s": None}
    if not used:
        return fields
    rejected: dict[str, dict[str, int]] = {}
    for r in used:
        for level, counts in (r.rejected_dict() or {}).items():  # not None: r.rejected is set
            for reason, c in counts.items():
                rejected.setdefault(level, {})[reason] = rejected.get(level, {}).get(reason, 0) + c
    refinements = [x for r in used for x in r.refinements]
    fields["feasibility"] = {"rejected": rejected, "refinements": len(refinements),
                             "refinement_failures": sum(x["failed_action"] is not None for x in refinements)}
    fields["feasibility_time_s"] = round_m(sum(r.timings.get("feasibility", 0.0) for r in used))
    fields["plan_refine_time_s"] = round_m(sum(r.timings.get("refine", 0.0) for r in used))
    return fields


def rounded_all(errors: Sequence[float] | None) -> list[float | None] | None:
    """A row's `effect_error_m` from `dynamics_errors` (m per executed action; None without a Dynamics Model)."""
    return None if errors is None else [round_m(e) for e in errors]


def has_abstraction(models) -> bool:
    """Whether rows get `steps`: a Symbolic Model and its domain to read the steps through."""
    return models.symbolic is not None and models.domain is not None


def step_records(models, states: Sequence[np.ndarray], actions, plan_states, infos, checker,
           errors: Sequence[float], scene: Sequence[int] | None = None) -> list[dict]:
    """The `steps` of a row: each step executed or attempted (states: X_0 .. X_m observed, m executed;
    infos: the skill's StepInfo per step, or None where it did not run; errors: `dynamics_errors` of
    the executed ones), through the abstraction (in the plan's sub-scene `scene`, if any)."""
    from tamp.sim.refine import step_failure

    out = []
    for step in symbolic_steps(models, states, actions, plan_states, errors, scene):
        info = infos[step.index] if step.index < len(infos) else None
        reason = checker.check(states[step.index], np.asarray([step.action], dtype=np.int64))[0]
        out.append({"operator": step.operator, "probability": round_m(step.probability, 4),
                    "on_plan": step.on_plan, "kinematic": "ok" if reason is None else str(reason.value),
                    "refined": info is not None and step_failure(info) is None and step.executed,
                    "match": step.match, "mismatched_bits": len(step.mismatches()) if step.match is not None else None,
                    "allowed": None if step.match is None else step.observed_effect is not None,
                    "error_m": round_m(step.dynamics_error_m)})
    return out


def prediction_records(models, states: Sequence[np.ndarray], actions) -> list[dict] | None:
    """A row's `predictions` (`tamp.planning.calibration`); None without a Dynamics Model."""
    if models.dynamics is None:
        return None
    from tamp.planning.calibration import step_predictions

    return [p.record() for p in step_predictions(models.dynamics, states, actions)]


def expected_misses(records: list[dict] | None, loop) -> list[dict] | None:
    """A closed loop's `predictions` with, per executed step, how far the block missed most landed from where the
    loop expected it (`expected_miss_m`: the Dynamics Model with the misses the loop trusted then,
    `tamp.planning.experience`), when the loop kept its experience."""
    if records is None or not loop.expected:
        return records
    observed = [np.asarray(X, dtype=float)[:, :3] for X in loop.states[1:]]
    return [{**r, "expected_miss_m": round(float(np.linalg.norm(X - e, axis=1).max(initial=0.0)), 6)}
            for r, X, e in zip(records, observed, loop.expected)]


def transition_records(states: Sequence[np.ndarray], actions, infos) -> list[dict]:
    """A row's `transitions`: per executed action (X, a, X', grasped, status), positions to 0.01 mm."""
    out = []
    for k, action in enumerate(actions[:len(states) - 1]):
        info = infos[k] if k < len(infos) else None
        out.append({"X": np.round(np.asarray(states[k], dtype=float), 5).tolist(),
                    "action": [int(v) for v in action],
                    "X_next": np.round(np.asarray(states[k + 1], dtype=float), 5).tolist(),
                    "grasped": -1 if info is None or not info.changed else int(info.grasped),  # as `tamp collect`
                    "status": "ok" if info is None else str(info.status.value)})
    return out


def row_cause(row: dict) -> list[str] | None:
    """[cause, sentence] of a failed row (`tamp.planning.causes`), from the row's own fields; None for a
    success or an error row."""
    if row.get("outcome") in (None, ERROR_OUTCOME):
        return None
    found = cause_of(row["outcome"], row.get("step_miss_m"), row.get("stop"), row.get("refine_failure"))
    return None if found is None else [str(found[0]), found[1]]


def failure_record(failure) -> dict | None:
    """A row's `refine_failure` from a tamp.sim.trajectory.RefinementFailure (None: none)."""
    return None if failure is None else failure.record()


__all__ = ["ERROR_OUTCOME", "MAX_CANDIDATES", "ROW_KEYS", "Row", "TIMING_KEYS", "as_lists", "candidate_records",
           "expected_misses",
           "failure_record", "feasibility_fields", "has_abstraction", "level1_stages", "level1_time",
           "prediction_records", "round_m", "rounded_all", "row_cause", "row_outcome", "search_expanded",
           "step_records", "transition_records"]
