"""`evaluate`: every method on every problem of a set, planned, refined and executed in Drake.

For each (problem, method) the planner runs with the learned models (timed alone, after a one-off
warm-up per object count), then the plan is refined (IK, collision-checked motions, grasps) and
executed: `fast` in the refinement's own world (as `tamp plan` does), `full` with the arm following
the refined trajectory under physics. `bilevel_replan` runs in closed loop instead: action by
action in a World of the chosen fidelity, replanning from each observed state, up to k - 1 rounds.
One JSON row per pair is appended (whole line, flushed) to OUT/rows.jsonl as it finishes; see
ROW_KEYS and `row_outcome` for the fields. OUT/meta.json records the models, the problem set, the
configuration and the package versions; OUT/symbols.json what the Symbolic Model's bits mean on
the set's scenes (`learned.interpret`).

`probabilistic_oracle` rows (the paper's measure, an execution oracle): the ranked plans of the
probabilistic planner are refined and executed from X_init one after the other, most frequent
first, until one succeeds or `EvalConfig.oracle_max_plans` were executed; `executed_plans` counts
them, and `plan` and the refinement fields are those of the last one executed.

`effect_error_m`: per executed action, the Dynamics Model's position error (metres, mean over the
objects) predicting that action's effect from the state the world was in before it: how well the
model the method plans with knows the world on the actions it chose (None without one).

`step_miss_m`: the same with the worst block instead of the mean (how far the block the model missed
most landed from its prediction). `stop`: how a closed loop ended (`ClosedLoopResult.stop`; None: open
loop) and the last planning call's search status, kinematic rejections and predicted error. `cause`:
[cause, sentence] of a failed row (`tamp.planning.causes`, recomputed from these fields by
`row_cause`; None for a success). `bilevel_loop` rows are judged by where the loop ended: an action
it could not carry out changed nothing, and the loop went on.

`predictions`: per executed action, the Dynamics Model's prediction against the world
(`tamp.planning.calibration`): the action's class, the observed miss (the worst block, metres), the 95 %
bound of that miss and its two parts (the members' disagreement, the scatter they predict); None
without a Dynamics Model. `transitions`: per executed action, the observed state before and after it, the
block the gripper carried and the world's status: the data `tamp practice` learns from.

`steps`: per step executed or attempted (a refinement failure stops the plan; closed loop: every
action sent to the world), the step through the learned abstraction (`tamp.planning.steps`):
`operator` (None: no learned operator grounds the action in the observed symbols), `probability`
of the expected effect, `on_plan` (the symbols before equal the Level-1 plan's; None: no plan
symbols), `kinematic` (the planners' kinematic check of the action on the observed state before it:
"ok" or the reason), `refined`, `match` (the symbols observed after equal the expected ones; None:
not executed or no operator), `mismatched_bits`, `allowed` (the observed symbols are one of the
operator's learned effects, if not the expected one) and `error_m` (the Dynamics Model's error, as in
`effect_error_m`). None for rows without a Symbolic Model. `tamp refinability` aggregates them.

Closed-loop rows: `plan` holds the actions sent to the world (a failed one included, the loop goes
on from the observed state), `refine_time_s` the wall time of each World.step (planning and, in
`full`, execution), `level`, `predicted_error_m` and `candidates` are the first round's, timings are
summed over rounds and `rounds` counts the replanning rounds (planning calls - 1). `candidates` are
the planner's in its order (ranked symbolic plans, with the alternatives it verified after each).

Resumable: rows already in rows.jsonl are kept and not recomputed (a line cut short by a kill is
dropped and its row redone); an OUT started with other models, another problem file or another
configuration is refused. Worlds are reseeded for every row, so a row does not depend on which
worker computed it or what that worker did before: the rows are the same for any number of workers
(timings aside), as long as no planner hits its wall-clock limit.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import sys
import traceback
from contextlib import closing
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from evaluation.methods import METHODS, SYMBOLIC_BACKENDS, Method, load_method_models, required_files, resolve_methods
from evaluation.problems import read_problems
from guarded import LARGE, Schema, read_json, read_jsonl
from tamp.app.args import check_output_dir
from tamp.app.faults import Faults
from tamp.app.parallel import BACKENDS, run_tasks
from tamp.app.planner_flags import loop_flags_given
from tamp.app.problem import Problem
from tamp.errors import UserError
from tamp.planning.causes import cause_of, stop_record
from tamp.planning.config import Level1Config, LoopConfig, PlanConfig
from tamp.planning.results import LEVEL1_STAGES
from tamp.planning.steps import dynamics_errors, symbolic_steps
from tamp.planning.structs import OUTCOMES, Outcome
from tamp.planning.verify import goal_error
from tamp.records import atomic_write_text, exclusive, package_versions

if TYPE_CHECKING:
    from tamp.sim.feasibility import FeasibilityChecker

ROWS_NAME, META_NAME, LOCK_NAME, SYMBOLS_NAME = "rows.jsonl", "meta.json", ".evaluate.lock", "symbols.json"
FORMAT = "tamp-evaluation/1"
ROW_KEYS = ("problem", "n", "k", "run", "protocol", "moved", "method", "solved", "level", "plan", "planning_time_s",
            "level1_time_s", "predicted_error_m", "candidates", "refined", "refine_failure", "refine_time_s",
            "executed_actions", "executed_plans", "final_error_m", "success", "outcome", "rounds", "fidelity",
            "eps_m", "tau_verify_m", "symbolic_backend", "feasibility", "search_time_s", "feasibility_time_s",
            "plan_refine_time_s", "level1_stages_s", "search_expanded", "effect_error_m", "step_miss_m", "stop",
            "cause", "steps", "predictions", "transitions")
# the only fields that vary between runs
TIMING_KEYS = ("planning_time_s", "level1_time_s", "refine_time_s", "search_time_s", "feasibility_time_s",
               "plan_refine_time_s", "level1_stages_s")
ERROR_OUTCOME = Outcome.ERROR.value  # a pair that raised (see Evaluator.error_row); not one of OUTCOMES
MAX_CANDIDATES = 20
# meta.json fields that define the rows: a results directory is resumed only if all of them match.
# The inputs' contents, not their paths: moved models or a copied problem set resume the same rows.
DEFINING_KEYS = ("model_files", "problems_sha256", "config")


@dataclass(frozen=True)
class EvalConfig:
    """How to evaluate: the planner's configuration (`tamp plan` and `tamp demo` use the same one; its
    seed is each problem's, its feasibility each method's) and how plans are executed."""

    planner: PlanConfig = PlanConfig()
    fidelity: str = "fast"  # execution: "fast" (refinement's world) or "full" (arm under physics)
    oracle_max_plans: int = 20  # probabilistic_oracle: ranked plans executed at most, per problem
    workers: int = 1  # worker processes or Ray actors
    backend: str = "local"  # "local" process pool or "ray"
    address: str | None = None  # with backend "ray": the cluster to join (None: start a local one)
    progress: bool = True  # progress bar on stderr
    faults: Faults = Faults()  # closed loops: observation noise and a push (`tamp.app.faults`); none by default

    def __post_init__(self) -> None:
        if self.fidelity not in ("fast", "full"):
            raise UserError(f"--fidelity must be 'fast' or 'full', got {self.fidelity!r}")
        if self.backend not in BACKENDS:
            raise UserError(f"--backend must be one of {', '.join(BACKENDS)}, got {self.backend!r}")
        if self.planner.level1.backend not in SYMBOLIC_BACKENDS:
            raise UserError(f"--symbolic-backend must be one of {', '.join(SYMBOLIC_BACKENDS)}, "
                            f"got {self.planner.level1.backend!r}")
        for name in ("oracle_max_plans", "workers"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise UserError(f"--{name.replace('_', '-')} must be a positive integer, got {value!r}")

    @property
    def eps(self) -> float:
        return self.planner.verify.eps

    @property
    def tau_verify(self) -> float:
        return self.planner.verify.tau_verify

    @property
    def symbolic_backend(self) -> str:
        return self.planner.level1.backend

    def defining(self) -> dict[str, Any]:
        """The settings rows depend on (a results directory holds rows of one setting only)."""
        p = self.planner
        out = {"fidelity": self.fidelity, "eps_m": p.verify.eps, "tau_verify_m": p.verify.tau_verify,
               "n_domains": p.level1.n_domains,
               "search_time_limit_s": p.search.time_limit, "search_max_expansions": p.search.max_expansions,
               "search_stall": p.search.stall,
               "search_confident_m": p.search.confident, "search_look_on": p.search.look_on,
               "search_release_targets": p.search.release_targets,
               "search_max_fragility": p.search.max_fragility, "search_noise_m": p.search.noise,
               "level1_budget": p.level1.budget, "level1_time_budget_s": p.level1.time_budget,
               "level1_focus_from": p.level1.focus_from, "level1_focus_budget": p.level1.focus_budget,
               "level1_confident_m": p.level1.confident, "level1_cut": p.level1.cut,
               "level1_objects": p.level1.objects, "level1_serial": p.level1.serial,
               "keep_plan": p.loop.keep_plan, "on_course_m": p.loop.on_course,
               "symbolic_backend": p.level1.backend, "oracle_max_plans": self.oracle_max_plans}
        if p.level1.symbolic_time_limit != Level1Config.symbolic_time_limit:  # older directories stay resumable
            out["symbolic_time_limit_s"] = p.level1.symbolic_time_limit
        if p.level1.settle != Level1Config.settle:
            out["level1_settle"] = p.level1.settle
        if p.search.max_doubt is not None:
            out["search_max_doubt_m"] = p.search.max_doubt
        if p.search.greedy_from is not None:
            out["search_greedy_from"] = p.search.greedy_from
            out["search_greedy_h_unit_m"] = p.search.greedy_h_unit
            out["search_greedy_per_misplaced"] = p.search.greedy_per_misplaced
            out["search_greedy_stall"] = p.search.greedy_stall
            out["loop_greedy_search_budget"] = p.loop.greedy_search_budget
        # the loop that does not know k: the same, by the fields other than keep_plan and on_course (above)
        loop = {k: v for k, v in dataclasses.asdict(p.loop).items() if k not in ("keep_plan", "on_course")}
        if loop != {k: v for k, v in dataclasses.asdict(LoopConfig()).items() if k not in ("keep_plan", "on_course")}:
            out["loop"] = loop
        if self.faults.any:
            out["faults"] = {"noise_m": self.faults.noise_m, "push_m": self.faults.push_m}
        return out

    def plan_config(self, seed: int, feasibility: bool = True) -> PlanConfig:
        p = self.planner.with_seed(seed)
        return dataclasses.replace(p, kinematics=dataclasses.replace(p.kinematics, feasibility=feasibility))


# --------------------------------------------------------------------------- one (problem, method)

def row_outcome(solved: bool, refine_failure: dict | None, final_error: float, eps: float) -> Outcome:
    """The row's Outcome (see `tamp.planning.structs.Outcome`)."""
    return Outcome.of(solved, None if refine_failure is None else refine_failure["stage"], final_error, eps)


def _round(x: float | None, digits: int = 6) -> float | None:
    return None if x is None else round(float(x), digits)


def _actions(plan) -> list[list[int]] | None:
    return None if plan is None else [[int(v) for v in a] for a in plan]


def _level1_time(result) -> float:
    return sum(result.timings.get(k, 0.0) for k in LEVEL1_STAGES)


def _level1_stages(results: list) -> dict[str, float | None] | None:
    """Seconds per Level-1 stage (symbols, symbolic, verify), summed over planning calls; None without
    a symbolic level."""
    if not any("symbols" in r.timings for r in results):
        return None
    return {k: _round(sum(r.timings.get(k, 0.0) for r in results)) for k in LEVEL1_STAGES}


def _search_expanded(results: list) -> int | None:
    """Continuous-search expansions summed over planning calls; None when no call searched."""
    searched = [r.search.expanded for r in results if r.search is not None]
    return sum(searched) if searched else None


def _candidates(result) -> list[dict]:
    return [{"error_m": _round(c.error), "verified": None if c.verified is None else bool(c.verified),
             "count": int(c.count), "alternative_of": c.alternative_of}
            for c in result.candidates[:MAX_CANDIDATES]]


def _feasibility_fields(results: list) -> dict:
    """Row fields of kinematics in the planning loop, summed over planning calls (closed loop: rounds):
    rejections per level and reason, refinements tried and failed, check, search and refinement time."""
    used = [r for r in results if r.rejected is not None]
    fields: dict[str, Any]
    fields = {"feasibility": None, "search_time_s": _round(sum(r.timings.get("search", 0.0) for r in results)),
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
    fields["feasibility_time_s"] = _round(sum(r.timings.get("feasibility", 0.0) for r in used))
    fields["plan_refine_time_s"] = _round(sum(r.timings.get("refine", 0.0) for r in used))
    return fields


def _rounded(errors: Sequence[float] | None) -> list[float | None] | None:
    """A row's `effect_error_m` from `dynamics_errors` (m per executed action; None without a Dynamics Model)."""
    return None if errors is None else [_round(e) for e in errors]


def _has_abstraction(models) -> bool:
    """Whether rows get `steps`: a Symbolic Model and its domain to read the steps through."""
    return models.symbolic is not None and models.domain is not None


def _steps(models, states: Sequence[np.ndarray], actions, plan_states, infos, checker,
           errors: Sequence[float], scene: Sequence[int] | None = None) -> list[dict]:
    """The `steps` of a row: each step executed or attempted (states: X_0 .. X_m observed, m executed;
    infos: the skill's StepInfo per step, or None where it did not run; errors: `dynamics_errors` of
    the executed ones), through the abstraction (in the plan's sub-scene `scene`, if any)."""
    from tamp.sim.refine import step_failure

    out = []
    for step in symbolic_steps(models, states, actions, plan_states, errors, scene):
        info = infos[step.index] if step.index < len(infos) else None
        reason = checker.check(states[step.index], np.asarray([step.action], dtype=np.int64))[0]
        out.append({"operator": step.operator, "probability": _round(step.probability, 4),
                    "on_plan": step.on_plan, "kinematic": "ok" if reason is None else str(reason.value),
                    "refined": info is not None and step_failure(info) is None and step.executed,
                    "match": step.match, "mismatched_bits": len(step.mismatches()) if step.match is not None else None,
                    "allowed": None if step.match is None else step.observed_effect is not None,
                    "error_m": _round(step.dynamics_error_m)})
    return out


def _predictions(models, states: Sequence[np.ndarray], actions) -> list[dict] | None:
    """A row's `predictions` (`tamp.planning.calibration`); None without a Dynamics Model."""
    if models.dynamics is None:
        return None
    from tamp.planning.calibration import step_predictions

    return [p.record() for p in step_predictions(models.dynamics, states, actions)]


def _transitions(states: Sequence[np.ndarray], actions, infos) -> list[dict]:
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


def _failure(failure) -> dict | None:
    """A row's `refine_failure` from a tamp.sim.trajectory.RefinementFailure (None: none)."""
    return None if failure is None else failure.record()


class Evaluator:
    """Plans, refines and executes (problem, method) pairs; one per worker, reused for its lifetime."""

    def __init__(self, models: dict, config: EvalConfig) -> None:
        self.models, self.config = models, config
        self._warm: set[tuple[int, int]] = set()
        self._worlds: dict[str, Any] = {}
        self._checker: FeasibilityChecker | None = None
        self._warm_layouts: set[tuple[int, ...]] = set()

    def checker(self, problem: Problem):
        """This worker's kinematic feasibility checker (its own fast world), having observed the scene
        of problem.X_init as refinement starts it; the first scene of each layout (block types) pays
        the checker's one-off collision-model builds before any planner is timed."""
        if self._checker is None:
            from tamp.sim.feasibility import FeasibilityChecker

            self._checker = FeasibilityChecker()
        checker = self._checker
        scene = checker.reset(problem.X_init)
        layout = tuple(int(t) for t in scene.types)
        if layout not in self._warm_layouts:
            from tamp.planning.search import all_actions

            checker.check(problem.X_init, all_actions(problem.n))
            self._warm_layouts.add(layout)
        return checker

    def world(self, fidelity: str):
        """This worker's World of a fidelity (paths simplified: they are executed), reseeded as a new
        World(seed=0) would be, so that nothing depends on the rows computed before."""
        if fidelity not in self._worlds:
            from tamp.app.runner import executing_world

            self._worlds[fidelity] = executing_world(fidelity)
        world = self._worlds[fidelity]
        world.rng = np.random.default_rng(0)
        return world

    def warm_up(self, models, problem: Problem) -> None:
        """One-off costs for n objects, paid before any planner is timed: the symbolic planner's
        ground task cache and the networks' first forward passes."""
        key = (id(models), problem.n)
        if key in self._warm:
            return
        cfg = self.config.plan_config(problem.seed)
        if models.symbolic is not None and models.domain is not None:
            models.symbolic_planner(cfg.level1.backend, cfg.level1.symbolic_time_limit).task(problem.n)
            models.symbolic.symbols(problem.X_init)
        if models.dynamics is not None:
            models.dynamics.predict_effect(problem.X_init, np.zeros((1, 4), dtype=np.int64))
        self._warm.add(key)

    def run(self, problem: Problem, method_name: str) -> dict:
        """The result row of one method on one problem (keys ROW_KEYS; an error row if it raised)."""
        method, models = METHODS[method_name], self.models[method_name]
        try:
            self.warm_up(models, problem)
            body = self._closed_loop if method.closed_loop else self._open_loop
            fields = body(problem, method, models)
        except Exception as error:  # one pair's failure must not end the run: an error row with the traceback
            return self.error_row(problem, method_name, error)
        c = self.config
        row: dict[str, Any]
        row = {"problem": problem.name, "n": problem.n, "k": problem.k, "run": problem.run or 0,
               "protocol": problem.protocol, "moved": problem.moved, "method": method_name, **fields,
               "fidelity": c.fidelity, "eps_m": c.eps, "tau_verify_m": c.tau_verify,
               "symbolic_backend": c.symbolic_backend if method.symbolic else None}
        # the loop that does not know k goes on after an action it could not carry out: judged by where it ended
        failure = None if method.loop == "goal" and row["final_error_m"] < c.eps else row["refine_failure"]
        row["outcome"] = row_outcome(row["solved"], failure, row["final_error_m"], c.eps)
        row["success"] = row["outcome"] == Outcome.SUCCESS
        row["cause"] = row_cause(row)
        return {k: row[k] for k in ROW_KEYS}

    def error_row(self, problem: Problem, method_name: str, error: BaseException) -> dict:
        """The row of a pair that raised: outcome "error", the message in `error`, the traceback in
        `traceback`; the report lists it and leaves it out of the statistics."""
        c = self.config
        row: dict[str, Any]
        row = {"problem": problem.name, "n": problem.n, "k": problem.k, "run": problem.run or 0,
               "protocol": problem.protocol, "moved": problem.moved, "method": method_name, "solved": False,
               "level": None, "plan": None, "planning_time_s": 0.0, "level1_time_s": None,
               "predicted_error_m": None, "candidates": [], "refined": None, "refine_failure": None,
               "refine_time_s": [], "executed_actions": 0, "executed_plans": None, "final_error_m": None,
               "success": False, "outcome": Outcome.ERROR, "rounds": None, "fidelity": c.fidelity, "eps_m": c.eps,
               "tau_verify_m": c.tau_verify,
               "symbolic_backend": c.symbolic_backend if METHODS[method_name].symbolic else None}
        row = {k: row.get(k) for k in ROW_KEYS}  # fields an error row cannot have are None
        row["error"] = f"{type(error).__name__}: {error}"
        row["traceback"] = "".join(traceback.format_exception(type(error), error, error.__traceback__))
        return row

    def _open_loop(self, problem: Problem, method: Method, models) -> dict:
        from tamp.planning.methods import plan

        kinematics = self.checker(problem) if method.feasibility else None
        extra = {} if kinematics is None else {"kinematics": kinematics}
        result = plan(method.planner, models, problem.X_init, problem.X_goal,
                      self.config.plan_config(problem.seed, method.feasibility), **extra)
        fields = {**_feasibility_fields([result]), "level1_stages_s": _level1_stages([result]),
                  "search_expanded": _search_expanded([result]), "solved": result.solved, "level": result.level,
                  "plan": _actions(result.plan),
                  "planning_time_s": _round(result.timings["total"]), "level1_time_s": _round(_level1_time(result)),
                  "predicted_error_m": _round(result.predicted_error), "candidates": _candidates(result),
                  "refined": None, "refine_failure": None, "refine_time_s": [], "executed_actions": 0,
                  "executed_plans": 0, "final_error_m": _round(goal_error(problem.X_init, problem.X_goal)),
                  "rounds": None, "effect_error_m": None, "step_miss_m": None, "stop": stop_record(None, result),
                  "steps": None, "predictions": None, "transitions": None}
        if not result.solved:
            return fields
        plans = [(c.actions, c.states, c.objects) for c in result.candidates[:self.config.oracle_max_plans]] \
            if method.oracle else [(result.plan, result.plan_states, result.plan_scene)]
        for number, (actions, plan_states, scene) in enumerate(plans, start=1):
            outcome = self._execute(problem, actions, models, plan_states, scene)
            fields = {**fields, "plan": _actions(actions), **outcome, "executed_plans": number}
            if outcome["refined"] and outcome["final_error_m"] < self.config.eps:
                break
        return fields

    def _execute(self, problem: Problem, actions, models, plan_states=None, scene=None) -> dict:
        """Refine and execute one plan from X_init: the refinement fields of a row (`plan_states` of the
        sub-scene `scene`: a Level-1 plan's symbolic path)."""
        if not actions:  # the planner says the initial state meets the goal: nothing to refine
            return {"refined": True, "refine_failure": None, "refine_time_s": [], "executed_actions": 0,
                    "final_error_m": _round(goal_error(problem.X_init, problem.X_goal)), "effect_error_m": [],
                    "step_miss_m": [], "steps": [], "predictions": [], "transitions": []}
        from tamp.app.runner import execute_plan

        ex = execute_plan(actions, problem.X_init, problem.X_goal, self.config.fidelity, world=self.world("fast"))
        states = [problem.X_init, *ex.X_after]
        errors = dynamics_errors(models, states, actions)
        steps = _steps(models, states, actions, plan_states, ex.refined.infos, self.checker(problem),
                       errors or [], scene) if _has_abstraction(models) else None
        return {"refined": ex.refined.success, "refine_failure": _failure(ex.refined.failure),
                "refine_time_s": [_round(s.refine_time) for s in ex.refined.steps],
                "executed_actions": len(ex.refined.steps), "final_error_m": _round(ex.error),
                "effect_error_m": _rounded(errors),
                "step_miss_m": _rounded(dynamics_errors(models, states, actions, worst=True)), "steps": steps,
                "predictions": _predictions(models, states, actions),
                "transitions": _transitions(states, actions, ex.refined.infos)}

    def _closed_loop(self, problem: Problem, method: Method, models) -> dict:
        from tamp.app.runner import run_closed_loop
        from tamp.planning.closed_loop import replan_rounds

        kinematics = self.checker(problem) if method.feasibility else None
        rounds = replan_rounds(problem.k) if method.loop == "paper" else None
        run = run_closed_loop(method.planner, models, problem.X_init, problem.X_goal, rounds,
                              self.config.plan_config(problem.seed, method.feasibility), self.config.fidelity,
                              world=self.world(self.config.fidelity), kinematics=kinematics,
                              faults=self.config.faults if self.config.faults.any else None, fault_seed=problem.seed)
        out = run.loop
        first = out.rounds[0] if out.rounds else None
        solved = first is None or first.solved  # no round: the initial state already met the goal
        executed = len(out.executed)
        X_final = run.X_final if executed else problem.X_init  # the world's, not the (noisy) observation
        failure = run.first_failure
        errors = dynamics_errors(models, out.states, out.executed)
        return {**_feasibility_fields(out.rounds), "level1_stages_s": _level1_stages(out.rounds),
                "search_expanded": _search_expanded(out.rounds),
                "solved": solved, "level": None if first is None else first.level,
                "plan": _actions(out.executed) if solved else None,
                "planning_time_s": _round(sum(r.timings["total"] for r in out.rounds)),
                "level1_time_s": _round(sum(_level1_time(r) for r in out.rounds)),
                "predicted_error_m": None if first is None else _round(first.predicted_error) if solved else None,
                "candidates": [] if first is None else _candidates(first),
                "refined": (failure is None) if solved else None, "refine_failure": _failure(failure),
                "refine_time_s": [_round(sum(t)) for t in run.step_times], "executed_actions": executed,
                "executed_plans": None, "final_error_m": _round(goal_error(X_final, problem.X_goal)),
                "rounds": max(len(out.rounds) - 1, 0), "effect_error_m": _rounded(errors),
                "step_miss_m": _rounded(dynamics_errors(models, out.states, out.executed, worst=True)),
                "stop": {**stop_record(out.stop, out.rounds[-1] if out.rounds else None),
                         **({"faults": run.faults} if run.faults else {})},
                "steps": self._loop_steps(problem, models, run, errors or []),
                "predictions": _predictions(models, out.states, out.executed),
                "transitions": _transitions(out.states, out.executed, run.infos)}

    def _loop_steps(self, problem: Problem, models, run, errors: Sequence[float]) -> list[dict] | None:
        """The `steps` of a closed loop: each action sent to the world (`tamp.app.steps.loop_steps`)."""
        if not _has_abstraction(models):
            return None
        from tamp.app.steps import loop_steps

        checker, out = self.checker(problem), []
        for s in loop_steps(run):
            (step,) = _steps(models, s.states, [s.action], s.plan_states, [s.info], checker,
                             errors[s.index:s.index + 1], s.scene)
            out.append({**step, "round": s.round, "plan": s.plan})  # which round chose it, planned or kept
        return out


# --------------------------------------------------------------------------- workers

class EvalWorker:
    """One worker's Evaluator (models loaded once), for `tamp.app.parallel.run_tasks`."""

    def __init__(self, models_dir: str, methods: list[str], models: dict | None, config: EvalConfig) -> None:
        import torch

        torch.set_num_threads(1)
        self.evaluator = Evaluator(models if models is not None else load_method_models(models_dir, methods), config)

    def run(self, task: tuple[Problem, str]) -> dict:
        problem, method = task
        # Ray hands numpy arrays over read-only (zero copy); the planners expect their own arrays
        problem = dataclasses.replace(problem, X_init=problem.X_init.copy(), X_goal=problem.X_goal.copy())
        return self.evaluator.run(problem, method)


# --------------------------------------------------------------------------- the results directory

def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _model_files(models_dir: Path) -> dict[str, str]:
    """sha256 of every model file any method could load (those that exist), by relative path."""
    paths = {p for m in METHODS for p in required_files(models_dir, m) if p.is_file()}
    return {str(p.relative_to(models_dir)): _sha256(p) for p in sorted(paths)}


def read_rows(path: str | Path) -> list[dict]:
    """The rows of a rows.jsonl file (a last line cut short by a kill is left out)."""
    return _scan_rows(Path(path))[0]


# what a resumed run needs of a row already written (the report checks the rest: evaluation.report.rows)
_ROW = Schema({"type": "object", "required": ["problem", "method"],
               "properties": {"problem": {"type": "string"}, "method": {"type": "string"}}})
# meta.json fields a resumed run compares and extends
META_SCHEMA = Schema({"type": "object", "required": ["format", *DEFINING_KEYS], "properties": {
    "format": {"enum": [FORMAT]}, "model_files": {"type": "object"}, "problems_sha256": {"type": "string"},
    "config": {"type": "object"}, "methods": {"type": "array", "items": {"type": "string"}},
    "runs": {"type": "array"}, "versions": {"type": "object"}}})


def _scan_rows(path: Path) -> tuple[list[dict], int]:
    """(complete rows, byte length of the complete lines); the text after the last newline is a row cut
    short by a kill (left out); a broken line before it is an error."""
    if not path.exists():
        return [], 0
    lines = read_jsonl(path, "rows file", LARGE, unfinished=True)
    for number, row in lines.values:
        _ROW.check(row, f"{path} line {number} (the file was damaged by something other than an interrupted "
                   "evaluation)")
    return [row for _, row in lines.values], lines.end


def _prepare(out: Path, meta: dict) -> None:
    """Create OUT/meta.json, or check that OUT holds rows of the same models, problems and config."""
    path = out / META_NAME
    if not path.exists():
        if (out / ROWS_NAME).exists():
            raise UserError(f"{out} has {ROWS_NAME} but no {META_NAME}; give a new --out directory")
        atomic_write_text(path, json.dumps(meta, indent=2) + "\n")
        return
    old = read_json(path, "meta file")
    if not isinstance(old, dict) or old.get("format") != FORMAT:
        raise UserError(f"{path} is not the meta file of a `tamp evaluate` results directory")
    META_SCHEMA.check(old, str(path))
    diffs = []
    for key in DEFINING_KEYS:
        a, b = old.get(key), meta[key]
        if isinstance(a, dict) and isinstance(b, dict):
            diffs += [f"{key}.{k}: {_short(a.get(k))} there, {_short(b.get(k))} now"
                      for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        elif a != b:
            diffs.append(f"{key}: {_short(a)} there, {_short(b)} now")
    if diffs:
        raise UserError(f"{out} holds rows of other inputs ({'; '.join(diffs[:3])}); use a new --out "
                         "directory, or the same models, problem set and settings to resume")
    if old.get("versions") != meta["versions"]:
        from tqdm import tqdm

        tqdm.write(f"warning: {out} was started with other package versions ({old.get('versions')}); "
                   "resuming anyway", file=sys.stderr)
    old["models_dir"], old["problems"] = meta["models_dir"], meta["problems"]  # where the inputs are now
    old["methods"] = [m for m in METHODS if m in set(old.get("methods", [])) | set(meta["methods"])]
    old["runs"] = old.get("runs", []) + meta["runs"]
    atomic_write_text(path, json.dumps(old, indent=2) + "\n")


def _short(value) -> str:
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _write_symbols(out: Path, problems: Sequence[Problem], models_dir: Path, methods: Sequence[str],
                   models: dict | None) -> None:
    """OUT/symbols.json: what the Symbolic Model's bits mean on the set's scenes (`learned.interpret`),
    for the report; nothing when no method plans with the default Symbolic Model."""
    users = [m for m in methods if METHODS[m].symbolic and METHODS[m].models == "default"]
    if not users:
        return
    from learned.interpret import interpret_symbols

    if models is not None:
        symbolic = getattr(models[users[0]], "symbolic", None)
    else:
        import learned
        from tamp.planning.models import SYMBOLIC_FILE

        symbolic = learned.load_model(models_dir / SYMBOLIC_FILE)
    if symbolic is None:
        return
    report = interpret_symbols(symbolic.symbols, [X for p in problems for X in (p.X_init, p.X_goal)])
    atomic_write_text(out / SYMBOLS_NAME, json.dumps([b.to_dict() for b in report], indent=1) + "\n")


def refuse_inapplicable(methods: Sequence[str], config: EvalConfig) -> None:
    """UserError for a setting that none of `methods` would apply (a flag given in vain): meta.json
    records the settings the rows were computed with, and nothing else."""
    names = ", ".join(methods)
    if not any(METHODS[m].closed_loop for m in methods):
        given = (["--noise/--push"] if config.faults.any else []) + loop_flags_given(config.planner)
        if given:
            raise UserError(f"{given[0]} acts on closed loops (bilevel_replan, bilevel_loop); none of the methods "
                            f"({names}) runs one")
    if not any(METHODS[m].loop == "goal" for m in methods) and (
            given := loop_flags_given(config.planner, until_goal_only=True)):
        raise UserError(f"{given[0]} sets the loop that runs until the goal (bilevel_loop); none of the methods "
                        f"({names}) runs it")
    if config.oracle_max_plans != EvalConfig.oracle_max_plans and not any(METHODS[m].oracle for m in methods):
        raise UserError(f"--oracle-max-plans sets probabilistic_oracle; none of the methods ({names}) is it")


def evaluate(models_dir: str | Path, problems_path: str | Path, out_dir: str | Path,
             methods: Sequence[str] | None = None, config: EvalConfig = EvalConfig(),
             models: dict | None = None) -> Path:
    """Evaluate `methods` (default: evaluation.methods.default_methods) on every problem of the set.

    Appends the missing rows to OUT/rows.jsonl and returns its path. `models` (method name ->
    tamp.planning.models.Models) replaces loading them from `models_dir`, for tests with stub models.
    """
    from tqdm import tqdm
    # Every input is checked before anything is written: the output folder, the problems (each scene,
    # by tamp.planning.validate), the models (loaded once here) and every problem's size against them.
    models_dir, problems_path, out = Path(models_dir).resolve(), Path(problems_path).resolve(), Path(out_dir)
    check_output_dir(out, "--out")
    if models is None:
        methods = resolve_methods(models_dir, methods)
    else:
        methods = [m for m in METHODS if m in (methods or models)]
        missing = [m for m in methods if m not in models]
        if missing:
            raise UserError(f"no models given for method {missing[0]}")
    refuse_inapplicable(methods, config)
    problems = read_problems(problems_path)
    loaded = models if models is not None else load_method_models(models_dir, methods)
    for method in methods:
        for p in problems:
            loaded[method].require_objects(p.n, f"{problems_path}: problem {p.name}")
    if models is None and config.workers == 1 and config.backend == "local":
        models = loaded  # one process: the models just loaded serve the run
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    meta = {"format": FORMAT, "models_dir": str(models_dir), "model_files": _model_files(models_dir),
            "problems": str(problems_path), "problems_sha256": _sha256(problems_path), "n_problems": len(problems),
            "config": config.defining(), "methods": methods, "versions": package_versions(), "started": started,
            "runs": [{"started": started, "methods": methods, "workers": config.workers, "backend": config.backend}]}
    out.mkdir(parents=True, exist_ok=True)
    with exclusive(out, LOCK_NAME, "tamp evaluate"):
        _prepare(out, meta)
        rows_path = out / ROWS_NAME
        rows, end = _scan_rows(rows_path)
        if rows_path.exists() and rows_path.stat().st_size > end:
            tqdm.write(f"warning: dropping the incomplete last line of {rows_path} (from an interrupted run); "
                       "that row is computed again", file=sys.stderr)
            os.truncate(rows_path, end)
        _write_symbols(out, problems, models_dir, methods, models)
        done = {(r["problem"], r["method"]) for r in rows}
        if len(done) < len(rows):
            raise UserError(f"{rows_path} holds a (problem, method) row twice; the file was edited")
        pairs = [(p, m) for p in problems for m in methods]
        tasks = [(p, m) for p, m in pairs if (p.name, m) not in done]
        with open(rows_path, "a") as f, tqdm(total=len(pairs), initial=len(pairs) - len(tasks), desc="evaluate",
                                             unit="row", disable=not config.progress, file=sys.stderr) as bar:
            if tasks:
                # closed on every exit (Ctrl-C between two rows included): the pool stops, its workers with it
                with closing(run_tasks(tasks, EvalWorker, (str(models_dir), methods, models, config),
                                       workers=config.workers, backend=config.backend,
                                       address=config.address)) as rows_run:
                    for row in rows_run:
                        if row["outcome"] == ERROR_OUTCOME:
                            tqdm.write(f"warning: problem {row['problem']}, method {row['method']}: {row['error']}; "
                                       f"recorded as an error row (traceback in {rows_path}), the run goes on",
                                       file=sys.stderr)
                        f.write(json.dumps(row) + "\n")
                        f.flush()
                        bar.update()
        return rows_path


def strip_timings(row: dict) -> dict:
    """A row without its wall-clock fields (what must agree between runs and worker counts)."""
    return {k: v for k, v in row.items() if k not in TIMING_KEYS}


__all__ = ["ERROR_OUTCOME", "EvalConfig", "Evaluator", "OUTCOMES", "ROW_KEYS", "evaluate", "read_rows",
           "refuse_inapplicable", "row_cause", "row_outcome", "strip_timings"]
