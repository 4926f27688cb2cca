"""`evaluate`: every method on every problem of a set, planned, refined and executed in Drake.

For each (problem, method) the planner runs with the learned models (timed alone, after a one-off
warm-up per object count), then the plan is refined (IK, collision-checked motions, grasps) and
executed: `fast` in the refinement's own world (as `tamp plan` does), `full` with the arm following
the refined trajectory under physics. The closed-loop methods run action by action in a World of the
chosen fidelity, replanning from each observed state. One JSON row per pair (`evaluation.row.Row`,
its schema) is appended (whole line, flushed) to OUT/rows.jsonl as it finishes. OUT/meta.json records
the models, the problem set, the configuration and the package versions; OUT/symbols.json what the
Symbolic Model's bits mean on the set's scenes (`learned.interpret`).

Resumable: rows already in rows.jsonl are kept and not recomputed (a line cut short by a kill is dropped and its row
redone); an OUT started with other models, another problem file or another configuration is refused. Worlds are
reseeded for every row, so a row does not depend on which worker computed it or what that worker did before: the
rows are the same for any number of workers (timings aside), as long as no planner hits its wall-clock limit.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import sys
import traceback
from contextlib import closing
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from evaluation.configuration import EvalConfig
from evaluation.methods import METHODS, Method, load_method_models, required_files, resolve_methods
from evaluation.problems import read_problems
from evaluation.row import (
    ERROR_OUTCOME,
    ROW_KEYS,
    TIMING_KEYS,
    Row,
    as_lists,
    candidate_records,
    expected_misses,
    failure_record,
    feasibility_fields,
    has_abstraction,
    level1_stages,
    level1_time,
    prediction_records,
    round_m,
    rounded_all,
    row_cause,
    row_outcome,
    search_expanded,
    step_records,
    transition_records,
)
from guarded import LARGE, Schema, append_line, atomic_write_json, dumps, read_json, read_jsonl
from tamp.app.args import check_output_dir
from tamp.app.parallel import run_tasks
from tamp.app.problem import Problem
from tamp.errors import UserError
from tamp.planning.causes import stop_record
from tamp.planning.steps import dynamics_errors
from tamp.planning.verify import goal_error
from tamp.planning.vocabulary import Loop, Outcome
from tamp.records import exclusive, output_dir, package_versions, source_commit

if TYPE_CHECKING:
    from tamp.sim.kinematic_checker import FeasibilityChecker

ROWS_NAME, META_NAME, LOCK_NAME, SYMBOLS_NAME = "rows.jsonl", "meta.json", ".evaluate.lock", "symbols.json"
FORMAT = "tamp-evaluation/1"
# meta.json fields that define the rows: a results directory is resumed only if all of them match.
# The inputs' contents, not their paths: moved models or a copied problem set resume the same rows.
DEFINING_KEYS = ("model_files", "problems_sha256", "config")


# --------------------------------------------------------------------------- one (problem, method)

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
            from tamp.sim.kinematic_checker import FeasibilityChecker

            self._checker = FeasibilityChecker()
        checker = self._checker
        scene = checker.reset(problem.X_init)
        layout = tuple(int(t) for t in scene.types)
        if layout not in self._warm_layouts:
            from tamp.planning.pruning import all_actions

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
        """One-off costs for n objects, paid before any planner is timed: the symbolic planner's tasks (of the scene
        and of Level 1's sub-scenes, `Level1Config.scene_sizes`) and the networks' first forward passes."""
        key = (id(models), problem.n)
        if key in self._warm:
            return
        cfg = self.config.plan_config(problem.seed)
        if models.symbolic is not None and models.domain is not None:
            for size in cfg.level1.scene_sizes(problem.n):  # Level 1's sub-scenes from focus_from blocks on
                models.symbolic_planner(cfg.level1.backend).task(size)
                models.symbolic.symbols(problem.X_init[:size])
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
        failure = None if method.loop == Loop.UNTIL_GOAL and row["final_error_m"] < c.eps else row["refine_failure"]
        row["outcome"] = row_outcome(row["solved"], failure, row["final_error_m"], c.eps)
        row["success"] = row["outcome"] == Outcome.SUCCESS
        row["cause"] = row_cause(row)
        return Row(**{k: row[k] for k in ROW_KEYS}).to_dict()

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
        every: dict[str, Any] = {k: row.get(k) for k in ROW_KEYS}  # fields an error row cannot have are None
        row = Row(**every).to_dict()
        row["error"] = f"{type(error).__name__}: {error}"
        row["traceback"] = "".join(traceback.format_exception(type(error), error, error.__traceback__))
        return row

    def _open_loop(self, problem: Problem, method: Method, models) -> dict:
        from tamp.planning.planners import plan

        kinematics = self.checker(problem) if method.feasibility else None
        extra = {} if kinematics is None else {"kinematics": kinematics}
        result = plan(method.planner, models, problem.X_init, problem.X_goal,
                      self.config.plan_config(problem.seed, method.feasibility), **extra)
        fields = {**feasibility_fields([result]), "level1_stages_s": level1_stages([result]),
                  "search_expanded": search_expanded([result]), "solved": result.solved, "level": result.level,
                  "plan": as_lists(result.plan),
                  "planning_time_s": round_m(result.timings["total"]), "level1_time_s": round_m(level1_time(result)),
                  "predicted_error_m": round_m(result.predicted_error), "candidates": candidate_records(result),
                  "refined": None, "refine_failure": None, "refine_time_s": [], "executed_actions": 0,
                  "executed_plans": 0, "final_error_m": round_m(goal_error(problem.X_init, problem.X_goal)),
                  "rounds": None, "effect_error_m": None, "step_miss_m": None, "stop": stop_record(None, result),
                  "steps": None, "predictions": None, "transitions": None}
        if not result.solved:
            return fields
        plans = [(c.actions, c.states, c.objects) for c in result.candidates[:self.config.oracle_max_plans]] \
            if method.oracle else [(result.plan, result.plan_states, result.plan_scene)]
        for number, (actions, plan_states, scene) in enumerate(plans, start=1):
            outcome = self._execute(problem, actions, models, plan_states, scene)
            fields = {**fields, "plan": as_lists(actions), **outcome, "executed_plans": number}
            if outcome["refined"] and outcome["final_error_m"] < self.config.eps:
                break
        return fields

    def _execute(self, problem: Problem, actions, models, plan_states=None, scene=None) -> dict:
        """Refine and execute one plan from X_init: the refinement fields of a row (`plan_states` of the
        sub-scene `scene`: a Level-1 plan's symbolic path)."""
        if not actions:  # the planner says the initial state meets the goal: nothing to refine
            return {"refined": True, "refine_failure": None, "refine_time_s": [], "executed_actions": 0,
                    "final_error_m": round_m(goal_error(problem.X_init, problem.X_goal)), "effect_error_m": [],
                    "step_miss_m": [], "steps": [], "predictions": [], "transitions": []}
        from tamp.app.runner import execute_plan

        ex = execute_plan(actions, problem.X_init, problem.X_goal, self.config.fidelity, world=self.world("fast"))
        states = [problem.X_init, *ex.X_after]
        errors = dynamics_errors(models, states, actions)
        steps = step_records(models, states, actions, plan_states, ex.refined.infos, self.checker(problem),
                       errors or [], scene) if has_abstraction(models) else None
        return {"refined": ex.refined.success, "refine_failure": failure_record(ex.refined.failure),
                "refine_time_s": [round_m(s.refine_time) for s in ex.refined.steps],
                "executed_actions": len(ex.refined.steps), "final_error_m": round_m(ex.error),
                "effect_error_m": rounded_all(errors),
                "step_miss_m": rounded_all(dynamics_errors(models, states, actions, worst=True)), "steps": steps,
                "predictions": prediction_records(models, states, actions),
                "transitions": transition_records(states, actions, ex.refined.infos)}

    def _closed_loop(self, problem: Problem, method: Method, models) -> dict:
        from tamp.app.observation import rig_for
        from tamp.app.runner import run_episode
        from tamp.planning.closed_loop import replan_rounds

        kinematics = self.checker(problem) if method.feasibility else None
        rounds = replan_rounds(problem.k) if method.loop == Loop.PAPER else None
        run = run_episode(method.planner, models, problem.X_init, problem.X_goal,
                          self.config.plan_config(problem.seed, method.feasibility), self.config.fidelity,
                          closed_loop=True, rounds=rounds, world=self.world(self.config.fidelity),
                          kinematics=kinematics, faults=self.config.faults if self.config.faults.any else None,
                          fault_seed=problem.seed, cameras=rig_for(self.config.perception)).run
        assert run is not None  # a closed loop
        out = run.loop
        first = out.rounds[0] if out.rounds else None
        solved = first is None or first.solved  # no round: the initial state already met the goal
        executed = len(out.executed)
        X_final = run.X_final if executed else problem.X_init  # the world's, not the (noisy) observation
        failure = run.first_failure
        errors = dynamics_errors(models, out.states, out.executed)
        return {**feasibility_fields(out.rounds), "level1_stages_s": level1_stages(out.rounds),
                "search_expanded": search_expanded(out.rounds),
                "solved": solved, "level": None if first is None else first.level,
                "plan": as_lists(out.executed) if solved else None,
                "planning_time_s": round_m(sum(r.timings["total"] for r in out.rounds)),
                "level1_time_s": round_m(sum(level1_time(r) for r in out.rounds)),
                "predicted_error_m": None if first is None else round_m(first.predicted_error) if solved else None,
                "candidates": [] if first is None else candidate_records(first),
                "refined": (failure is None) if solved else None, "refine_failure": failure_record(failure),
                "refine_time_s": [round_m(sum(t)) for t in run.step_times], "executed_actions": executed,
                "executed_plans": None, "final_error_m": round_m(goal_error(X_final, problem.X_goal)),
                "rounds": max(len(out.rounds) - 1, 0), "effect_error_m": rounded_all(errors),
                "step_miss_m": rounded_all(dynamics_errors(models, out.states, out.executed, worst=True)),
                "stop": {**stop_record(out.stop, out.rounds[-1] if out.rounds else None),
                         **({"faults": run.faults} if run.faults else {}),
                         **({"perception": perception} if (perception := run.perception_record()) else {}),
                         **({"remembered": len(out.experience.trusted)} if out.experience is not None else {})},
                "steps": self._loop_steps(problem, models, run, errors or []),
                "predictions": expected_misses(prediction_records(models, out.states, out.executed), out),
                "transitions": transition_records(out.states, out.executed, run.infos)}

    def _loop_steps(self, problem: Problem, models, run, errors: Sequence[float]) -> list[dict] | None:
        """The `steps` of a closed loop: each action sent to the world (`tamp.app.step_report.loop_steps`)."""
        if not has_abstraction(models):
            return None
        from tamp.app.step_report import loop_steps

        checker, out = self.checker(problem), []
        for s in loop_steps(run):
            (step,) = step_records(models, s.states, [s.action], s.plan_states, [s.info], checker,
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
        atomic_write_json(path, meta, indent=2)
        return
    old = read_json(path, "meta file")
    if not isinstance(old, dict) or old.get("format") != FORMAT:
        raise UserError(f"{path} is not the meta file of a `tamp evaluate` results directory")
    META_SCHEMA.check(old, str(path))
    now = json.loads(json.dumps(meta))  # as it would read back: tuples (a push's range) are lists there
    diffs = [d for key in DEFINING_KEYS for d in _differences(key, old.get(key), now[key])]
    if diffs:
        what = "another configuration" if any(d.startswith("config") for d in diffs) else "other inputs"
        raise UserError(f"{out} holds rows made with {what} ({'; '.join(diffs[:3])}); use a new --out "
                        "directory, or the same models, problem set and configuration to resume")
    if old.get("versions") != meta["versions"]:
        from tqdm import tqdm

        tqdm.write(f"warning: {out} was started with other package versions ({old.get('versions')}); "
                   "resuming anyway", file=sys.stderr)
    old["models_dir"], old["problems"] = meta["models_dir"], meta["problems"]  # where the inputs are now
    old["methods"] = [m for m in METHODS if m in set(old.get("methods", [])) | set(meta["methods"])]
    old["runs"] = old.get("runs", []) + meta["runs"]
    atomic_write_json(path, old, indent=2)


def _differences(name: str, there, now) -> list[str]:
    """What differs between two JSON values, named down to the innermost differing setting."""
    if isinstance(there, dict) and isinstance(now, dict):
        return [d for k in sorted(set(there) | set(now)) for d in _differences(f"{name}.{k}", there.get(k), now.get(k))]
    return [] if there == now else [f"{name}: {_short(there)} there, {_short(now)} now"]


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
    atomic_write_json(out / SYMBOLS_NAME, [b.to_dict() for b in report], indent=1)


def refuse_inapplicable(methods: Sequence[str], config: EvalConfig) -> None:
    """UserError for faults that none of `methods` would meet (flags given in vain): only closed loops observe."""
    if config.faults.any and not any(METHODS[m].closed_loop for m in methods):
        raise UserError(f"--noise/--push act on closed loops (bilevel_replan, bilevel_loop); none of the methods "
                        f"({', '.join(methods)}) runs one")


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
            "runs": [{"started": started, "methods": methods, "workers": config.workers, "backend": config.backend,
                      "commit": source_commit()}]}
    with output_dir(out, "--out", own=(META_NAME, ROWS_NAME)), exclusive(out, LOCK_NAME, "tamp evaluate"):
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
        with tqdm(total=len(pairs), initial=len(pairs) - len(tasks), desc="evaluate", unit="row",
                  disable=not config.progress, file=sys.stderr) as bar:
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
                        append_line(rows_path, row_line(row))
                        bar.update()
        return rows_path


def row_line(row: dict) -> str:
    """A row as its line of rows.jsonl. A number that is not JSON (NaN, infinity: a model or a measurement gone
    wrong) is never written: the row becomes an error row that says which fields held one."""
    try:
        return dumps(row) + "\n"
    except ValueError:
        bad = sorted(k for k, v in row.items() if not _finite(v))
        error = f"non-finite number (NaN or infinity) in the row's {', '.join(bad) or 'values'}; nothing of it kept"
        kept = {k: v if _finite(v) else None for k, v in row.items()}
        return dumps({**kept, "outcome": ERROR_OUTCOME, "success": False, "error": error}) + "\n"


def _finite(value) -> bool:
    """Whether `value` holds no NaN or infinity (at any depth)."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(_finite(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return all(_finite(v) for v in value)
    return True


def strip_timings(row: dict) -> dict:
    """A row without its wall-clock fields (what must agree between runs and worker counts)."""
    return {k: v for k, v in row.items() if k not in TIMING_KEYS}


__all__ = ["Evaluator", "evaluate", "read_rows", "refuse_inapplicable", "strip_timings"]
