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
import fcntl
import hashlib
import json
import multiprocessing as mp
import os
import sys
import threading
import time
import traceback
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from evaluation.methods import METHODS, SYMBOLIC_BACKENDS, Method, load_method_models, required_files, resolve_methods
from evaluation.problems import atomic_write_text, read_problems
from tamp.planning.bilevel import PlanConfig
from tamp.app.collect import package_versions
from tamp.app.problem import Problem
from tamp.planning.verify import EPS_SUCCESS, TAU_VERIFY, goal_error

ROWS_NAME, META_NAME, LOCK_NAME, SYMBOLS_NAME = "rows.jsonl", "meta.json", ".evaluate.lock", "symbols.json"
FORMAT = "tamp-evaluation/1"
ROW_KEYS = ("problem", "n", "k", "run", "protocol", "moved", "method", "solved", "level", "plan", "planning_time_s",
            "level1_time_s", "predicted_error_m", "candidates", "refined", "refine_failure", "refine_time_s",
            "executed_actions", "executed_plans", "final_error_m", "success", "outcome", "rounds", "fidelity",
            "eps_m", "tau_verify_m", "symbolic_backend", "feasibility", "search_time_s", "feasibility_time_s",
            "plan_refine_time_s")
# the only fields that vary between runs
TIMING_KEYS = ("planning_time_s", "level1_time_s", "refine_time_s", "search_time_s", "feasibility_time_s",
               "plan_refine_time_s")
OUTCOMES = ("success", "no_plan", "kinematic_failure", "refinement_failure", "wrong_plan")
ERROR_OUTCOME = "error"  # a pair that raised (see Evaluator.error_row); not one of OUTCOMES
MAX_CANDIDATES = 20
# meta.json fields that define the rows: a results directory is resumed only if all of them match
DEFINING_KEYS = ("models_dir", "model_files", "problems", "problems_sha256", "config")
LEVEL1_STAGES = ("symbols", "symbolic", "verify")


@dataclass(frozen=True)
class EvalConfig:
    """How to evaluate. Lengths in metres, times in seconds."""

    fidelity: str = "fast"  # execution: "fast" (refinement's world) or "full" (arm under physics)
    eps: float = EPS_SUCCESS  # success: every object within eps of its goal
    tau_verify: float = TAU_VERIFY  # Level-1 verification threshold
    n_domains: int = 100  # N sampled symbolic domains
    search_time_limit: float = 10.0  # continuous search, per planning call
    search_max_expansions: int = 5000  # continuous search node limit, per planning call
    level1_expansions: int | None = PlanConfig.level1_expansions  # symbolic search expansions, all N domains
    level1_time_budget: float | None = PlanConfig.level1_time_budget  # all N symbolic planner calls of a call
    symbolic_backend: str = "python"  # "python" (in-process search) or "fd" (Fast Downward, the paper's)
    oracle_max_plans: int = 20  # probabilistic_oracle: ranked plans executed at most, per problem
    workers: int = 1  # worker processes or Ray actors
    backend: str = "local"  # "local" process pool or "ray"
    progress: bool = True  # progress bar on stderr

    def __post_init__(self) -> None:
        if self.fidelity not in ("fast", "full"):
            raise ValueError(f"--fidelity must be 'fast' or 'full', got {self.fidelity!r}")
        if self.backend not in ("local", "ray"):
            raise ValueError(f"--backend must be 'local' or 'ray', got {self.backend!r}")
        if self.symbolic_backend not in SYMBOLIC_BACKENDS:
            raise ValueError(f"--symbolic-backend must be one of {', '.join(SYMBOLIC_BACKENDS)}, "
                             f"got {self.symbolic_backend!r}")
        if isinstance(self.oracle_max_plans, bool) or not isinstance(self.oracle_max_plans, int) \
                or self.oracle_max_plans < 1:
            raise ValueError(f"--oracle-max-plans must be a positive integer, got {self.oracle_max_plans!r}")
        if isinstance(self.workers, bool) or not isinstance(self.workers, int) or self.workers < 1:
            raise ValueError(f"--workers must be a positive integer, got {self.workers!r}")
        for name in ("eps", "tau_verify", "search_time_limit"):
            if not getattr(self, name) > 0:
                raise ValueError(f"EvalConfig.{name} must be positive, got {getattr(self, name)}")
        if self.n_domains < 1 or self.search_max_expansions < 1:
            raise ValueError("--n-domains and the node limit must be positive integers")

    def defining(self) -> dict[str, Any]:
        """The settings rows depend on (a results directory holds rows of one setting only)."""
        return {"fidelity": self.fidelity, "eps_m": self.eps, "tau_verify_m": self.tau_verify,
                "n_domains": self.n_domains, "search_time_limit_s": self.search_time_limit,
                "search_max_expansions": self.search_max_expansions, "level1_expansions": self.level1_expansions,
                "level1_time_budget_s": self.level1_time_budget, "symbolic_backend": self.symbolic_backend,
                "oracle_max_plans": self.oracle_max_plans}

    def plan_config(self, seed: int, feasibility: bool = True) -> PlanConfig:
        from tamp.planning.search import SearchConfig

        return PlanConfig(n_domains=self.n_domains, seed=seed, tau_verify=self.tau_verify, eps=self.eps,
                          feasibility=feasibility,
                          backend=self.symbolic_backend,
                          level1_expansions=self.level1_expansions, level1_time_budget=self.level1_time_budget,
                          search=SearchConfig(max_expansions=self.search_max_expansions,
                                                 time_limit=self.search_time_limit))


# --------------------------------------------------------------------------- one (problem, method)

def row_outcome(solved: bool, refine_failure: dict | None, final_error: float, eps: float) -> str:
    """no_plan | kinematic_failure (IK) | refinement_failure (motion, grasp) | wrong_plan | success."""
    if not solved:
        return "no_plan"
    if refine_failure is not None:
        return "kinematic_failure" if refine_failure["stage"] == "ik" else "refinement_failure"
    return "success" if final_error < eps else "wrong_plan"


def _round(x: float | None, digits: int = 6) -> float | None:
    return None if x is None else round(float(x), digits)


def _actions(plan) -> list[list[int]] | None:
    return None if plan is None else [[int(v) for v in a] for a in plan]


def _level1_time(result) -> float:
    return sum(result.timings.get(k, 0.0) for k in LEVEL1_STAGES)


def _candidates(result) -> list[dict]:
    return [{"error_m": _round(c.error), "verified": None if c.verified is None else bool(c.verified),
             "count": int(c.count), "alternative_of": c.alternative_of}
            for c in result.candidates[:MAX_CANDIDATES]]


def _feasibility_fields(results: list) -> dict:
    """Row fields of kinematics in the planning loop, summed over planning calls (closed loop: rounds):
    rejections per level and reason, refinements tried and failed, check, search and refinement time."""
    used = [r for r in results if r.rejected is not None]
    fields = {"feasibility": None, "search_time_s": _round(sum(r.timings.get("search", 0.0) for r in results)),
              "feasibility_time_s": None, "plan_refine_time_s": None}
    if not used:
        return fields
    rejected: dict[str, dict[str, int]] = {}
    for r in used:
        for level, counts in r.rejected_dict().items():
            for reason, c in counts.items():
                rejected.setdefault(level, {})[reason] = rejected.get(level, {}).get(reason, 0) + c
    refinements = [x for r in used for x in r.refinements]
    fields["feasibility"] = {"rejected": rejected, "refinements": len(refinements),
                             "refinement_failures": sum(x["failed_action"] is not None for x in refinements)}
    fields["feasibility_time_s"] = _round(sum(r.timings.get("feasibility", 0.0) for r in used))
    fields["plan_refine_time_s"] = _round(sum(r.timings.get("refine", 0.0) for r in used))
    return fields


def _failure(index: int, stage: str, where: str, reason: str) -> dict:
    return {"action": int(index), "stage": stage, "where": where, "reason": reason}


class Evaluator:
    """Plans, refines and executes (problem, method) pairs; one per worker, reused for its lifetime."""

    def __init__(self, models: dict, config: EvalConfig) -> None:
        self.models, self.config = models, config
        self._warm: set[tuple[int, int]] = set()
        self._worlds: dict[str, Any] = {}
        self._checker = None
        self._warm_layouts: set[tuple[int, ...]] = set()

    def checker(self, problem: Problem):
        """This worker's kinematic feasibility checker (its own fast world), having observed the scene
        of problem.X_init as refinement starts it; the first scene of each layout (block types) pays
        the checker's one-off collision-model builds before any planner is timed."""
        if self._checker is None:
            from tamp.sim.feasibility import FeasibilityChecker

            self._checker = FeasibilityChecker()
        checker = self._checker
        checker.reset(problem.X_init)
        layout = tuple(int(t) for t in checker.scene.types)
        if layout not in self._warm_layouts:
            from tamp.planning.search import all_actions

            checker.check(problem.X_init, all_actions(problem.n))
            self._warm_layouts.add(layout)
        return checker

    def world(self, fidelity: str):
        """This worker's World of a fidelity (paths simplified: they are executed), reseeded as a new
        World(seed=0) would be, so that nothing depends on the rows computed before."""
        if fidelity not in self._worlds:
            from tamp.sim import World, WorldConfig

            self._worlds[fidelity] = World(WorldConfig(fidelity=fidelity, simplify_paths=True))
        world = self._worlds[fidelity]
        world.rng = np.random.default_rng(0)
        world.observer = None
        return world

    def warm_up(self, models, problem: Problem) -> None:
        """One-off costs for n objects, paid before any planner is timed: the symbolic planner's
        ground task cache and the networks' first forward passes."""
        key = (id(models), problem.n)
        if key in self._warm:
            return
        cfg = self.config.plan_config(problem.seed)
        if models.symbolic is not None and models.domain is not None:
            models.symbolic_planner(cfg.backend, cfg.symbolic_time_limit).ground(problem.n)
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
        row = {"problem": problem.name, "n": problem.n, "k": problem.k, "run": problem.run or 0,
               "protocol": problem.protocol, "moved": problem.moved, "method": method_name, **fields,
               "fidelity": c.fidelity, "eps_m": c.eps, "tau_verify_m": c.tau_verify,
               "symbolic_backend": c.symbolic_backend if method.symbolic else None}
        row["outcome"] = row_outcome(row["solved"], row["refine_failure"], row["final_error_m"], c.eps)
        row["success"] = row["outcome"] == "success"
        return {k: row[k] for k in ROW_KEYS}

    def error_row(self, problem: Problem, method_name: str, error: BaseException) -> dict:
        """The row of a pair that raised: outcome "error", the message in `error`, the traceback in
        `traceback`; the report lists it and leaves it out of the statistics."""
        c = self.config
        row = {"problem": problem.name, "n": problem.n, "k": problem.k, "run": problem.run or 0,
               "protocol": problem.protocol, "moved": problem.moved, "method": method_name, "solved": False,
               "level": None, "plan": None, "planning_time_s": 0.0, "level1_time_s": None,
               "predicted_error_m": None, "candidates": [], "refined": None, "refine_failure": None,
               "refine_time_s": [], "executed_actions": 0, "executed_plans": None, "final_error_m": None,
               "success": False, "outcome": "error", "rounds": None, "fidelity": c.fidelity, "eps_m": c.eps,
               "tau_verify_m": c.tau_verify, "symbolic_backend": c.symbolic_backend if METHODS[method_name].symbolic else None}
        row = {k: row.get(k) for k in ROW_KEYS}  # fields an error row cannot have are None
        row["error"] = f"{type(error).__name__}: {error}"
        row["traceback"] = "".join(traceback.format_exception(type(error), error, error.__traceback__))
        return row

    def _open_loop(self, problem: Problem, method: Method, models) -> dict:
        from tamp.planning.bilevel import plan

        kinematics = self.checker(problem) if method.feasibility else None
        extra = {} if kinematics is None else {"kinematics": kinematics}
        result = plan(method.planner, models, problem.X_init, problem.X_goal,
                      self.config.plan_config(problem.seed, method.feasibility), **extra)
        fields = {**_feasibility_fields([result]), "solved": result.solved, "level": result.level, "plan": _actions(result.plan),
                  "planning_time_s": _round(result.timings["total"]), "level1_time_s": _round(_level1_time(result)),
                  "predicted_error_m": _round(result.predicted_error), "candidates": _candidates(result),
                  "refined": None, "refine_failure": None, "refine_time_s": [], "executed_actions": 0,
                  "executed_plans": 0, "final_error_m": _round(goal_error(problem.X_init, problem.X_goal)),
                  "rounds": None}
        if not result.solved:
            return fields
        plans = [c.actions for c in result.candidates[:self.config.oracle_max_plans]] if method.oracle \
            else [result.plan]
        for number, actions in enumerate(plans, start=1):
            outcome = self._execute(problem, actions)
            fields = {**fields, "plan": _actions(actions), **outcome, "executed_plans": number}
            if outcome["refined"] and outcome["final_error_m"] < self.config.eps:
                break
        return fields

    def _execute(self, problem: Problem, actions) -> dict:
        """Refine and execute one plan from X_init: the refinement fields of a row."""
        if not actions:  # the planner says the initial state meets the goal: nothing to refine
            return {"refined": True, "refine_failure": None, "refine_time_s": [], "executed_actions": 0,
                    "final_error_m": _round(goal_error(problem.X_init, problem.X_goal))}
        from tamp.sim.refine import refine
        from tamp.planning.structs import PickPlace

        world = self.world("fast")
        refined = refine([PickPlace(*a) for a in actions], problem.X_init, world=world)
        if self.config.fidelity == "fast":  # the scene after the refined actions (not a failed one's)
            X_final = refined.X_predicted
        else:
            from tamp.sim.execute import execute

            X_final = execute(refined, partial=True).X_final
        f = refined.failure
        executed = len(refined.steps)
        return {"refined": refined.success,
                "refine_failure": None if f is None else _failure(f.action_index, f.stage, f.where, f.reason),
                "refine_time_s": [_round(s.refine_time) for s in refined.steps], "executed_actions": executed,
                "final_error_m": _round(goal_error(X_final if executed else problem.X_init, problem.X_goal))}

    def _closed_loop(self, problem: Problem, method: Method, models) -> dict:
        from tamp.planning.bilevel import plan_closed_loop, replan_rounds
        from tamp.sim.refine import FAILURE_STAGES, failed_at

        kinematics = self.checker(problem) if method.feasibility else None
        world = self.world(self.config.fidelity)
        X0 = world.reset(X=problem.X_init)
        if kinematics is not None:
            kinematics.observe(world.scene, world.q)
        failures: list[dict] = []
        step_times: list[float] = []

        def step(action):
            t = time.perf_counter()
            X, info = world.step(action)
            step_times.append(time.perf_counter() - t)
            if kinematics is not None:
                kinematics.observe(world.scene, world.q)
            if info.status != "ok" and not failures:
                failures.append(_failure(len(step_times) - 1, FAILURE_STAGES.get(info.status, "motion"), failed_at(info),
                                         info.reason))
            return X

        out = plan_closed_loop(method.planner, models, X0, problem.X_goal, step, replan_rounds(problem.k),
                               self.config.plan_config(problem.seed, method.feasibility), kinematics=kinematics)
        first = out.rounds[0] if out.rounds else None
        solved = first is None or first.solved  # no round: the initial state already met the goal
        executed = len(out.executed)
        X_final = out.X_final if executed else problem.X_init
        return {**_feasibility_fields(out.rounds), "solved": solved, "level": None if first is None else first.level,
                "plan": _actions(out.executed) if solved else None,
                "planning_time_s": _round(sum(r.timings["total"] for r in out.rounds)),
                "level1_time_s": _round(sum(_level1_time(r) for r in out.rounds)),
                "predicted_error_m": None if first is None else _round(first.predicted_error) if solved else None,
                "candidates": [] if first is None else _candidates(first),
                "refined": (not failures) if solved else None, "refine_failure": failures[0] if failures else None,
                "refine_time_s": [_round(t) for t in step_times], "executed_actions": executed,
                "executed_plans": None, "final_error_m": _round(goal_error(X_final, problem.X_goal)),
                "rounds": max(len(out.rounds) - 1, 0)}


# --------------------------------------------------------------------------- workers

_EVALUATOR: Evaluator | None = None  # the one Evaluator of a worker process


def _make_evaluator(models_dir: str, methods: list[str], models: dict | None, config: EvalConfig) -> Evaluator:
    import torch

    torch.set_num_threads(1)
    return Evaluator(models if models is not None else load_method_models(models_dir, methods), config)


def _init_pool_worker(models_dir: str, methods: list[str], models: dict | None, config: EvalConfig,
                      parent_pid: int) -> None:
    """Pool initializer: load the models once, and exit if the parent dies (e.g. kill -9)."""
    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()
    global _EVALUATOR
    _EVALUATOR = _make_evaluator(models_dir, methods, models, config)


def _pool_run(task: tuple[Problem, str]) -> dict:
    return _EVALUATOR.run(*task)


class RayEvaluator:
    """A Ray actor (wrapped with ray.remote at run time) holding one Evaluator."""

    def __init__(self, models_dir: str, methods: list[str], models: dict | None, config: EvalConfig) -> None:
        self.evaluator = _make_evaluator(models_dir, methods, models, config)

    def run(self, problem: Problem, method: str) -> dict:
        # Ray hands numpy arrays over read-only (zero copy); the planners expect their own arrays
        problem = dataclasses.replace(problem, X_init=problem.X_init.copy(), X_goal=problem.X_goal.copy())
        return self.evaluator.run(problem, method)


def _run_local(tasks, models_dir, methods, models, config: EvalConfig) -> Iterator[dict]:
    if config.workers == 1 or len(tasks) <= 1:
        evaluator = _make_evaluator(models_dir, methods, models, config)
        for problem, method in tasks:
            yield evaluator.run(problem, method)
        return
    ctx = mp.get_context("spawn")
    initargs = (models_dir, methods, models, config, os.getpid())
    with ctx.Pool(min(config.workers, len(tasks)), initializer=_init_pool_worker, initargs=initargs) as pool:
        yield from pool.imap_unordered(_pool_run, tasks, chunksize=1)


def _run_ray(tasks, models_dir, methods, models, config: EvalConfig) -> Iterator[dict]:
    import logging

    from tamp.app.collect import import_ray

    ray = import_ray()
    started_here = not ray.is_initialized()
    if started_here:
        ray.init(num_cpus=config.workers, include_dashboard=False, logging_level=logging.WARNING)
    try:
        Actor = ray.remote(num_cpus=1)(RayEvaluator)
        actors = [Actor.remote(models_dir, methods, models, config) for _ in range(min(config.workers, len(tasks)))]
        todo, pending = iter(tasks), {}

        def submit(actor) -> None:
            task = next(todo, None)
            if task is not None:
                pending[actor.run.remote(*task)] = actor

        for actor in actors * 2:  # two tasks in flight per actor hide the round trip
            submit(actor)
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            submit(pending.pop(done[0]))
            yield ray.get(done[0])
    finally:
        if started_here:
            ray.shutdown()


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


def _scan_rows(path: Path) -> tuple[list[dict], int]:
    """(complete rows, byte length of the complete lines); a broken line before the last is an error."""
    if not path.exists():
        return [], 0
    data = path.read_bytes()
    rows, end = [], 0
    lines = data.split(b"\n")
    for number, line in enumerate(lines[:-1], start=1):  # lines[-1]: after the last newline
        try:
            row = json.loads(line)
            if not isinstance(row, dict) or "problem" not in row or "method" not in row:
                raise ValueError("not a result row")
        except ValueError as error:
            raise ValueError(f"{path} line {number} is not a result row ({error}); the file was damaged "
                             "by something other than an interrupted evaluation") from None
        rows.append(row)
        end += len(line) + 1
    return rows, end


def _prepare(out: Path, meta: dict) -> None:
    """Create OUT/meta.json, or check that OUT holds rows of the same models, problems and config."""
    path = out / META_NAME
    if not path.exists():
        if (out / ROWS_NAME).exists():
            raise ValueError(f"{out} has {ROWS_NAME} but no {META_NAME}; give a new --out directory")
        atomic_write_text(path, json.dumps(meta, indent=2) + "\n")
        return
    try:
        old = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not valid JSON ({error})") from None
    if old.get("format") != FORMAT:
        raise ValueError(f"{path} is not the meta file of a `tamp evaluate` results directory")
    diffs = []
    for key in DEFINING_KEYS:
        a, b = old.get(key), meta[key]
        if isinstance(a, dict) and isinstance(b, dict):
            diffs += [f"{key}.{k}: {_short(a.get(k))} there, {_short(b.get(k))} now"
                      for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        elif a != b:
            diffs.append(f"{key}: {_short(a)} there, {_short(b)} now")
    if diffs:
        raise ValueError(f"{out} holds rows of other inputs ({'; '.join(diffs[:3])}); use a new --out "
                         "directory, or the same models, problem set and settings to resume")
    if old.get("versions") != meta["versions"]:
        from tqdm import tqdm

        tqdm.write(f"warning: {out} was started with other package versions ({old.get('versions')}); "
                   "resuming anyway", file=sys.stderr)
    old["methods"] = [m for m in METHODS if m in set(old.get("methods", [])) | set(meta["methods"])]
    old["runs"] = old.get("runs", []) + meta["runs"]
    atomic_write_text(path, json.dumps(old, indent=2) + "\n")


def _short(value) -> str:
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _lock(out: Path):
    f = open(out / LOCK_NAME, "w")
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        f.close()
        raise RuntimeError(f"another `tamp evaluate` is writing to {out}") from None
    return f


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


def evaluate(models_dir: str | Path, problems_path: str | Path, out_dir: str | Path,
             methods: Sequence[str] | None = None, config: EvalConfig = EvalConfig(),
             models: dict | None = None) -> Path:
    """Evaluate `methods` (default: evaluation.methods.default_methods) on every problem of the set.

    Appends the missing rows to OUT/rows.jsonl and returns its path. `models` (method name ->
    tamp.planning.models.Models) replaces loading them from `models_dir`, for tests with stub models.
    """
    from tqdm import tqdm

    from tamp.app.cli import check_output_dir

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
            raise ValueError(f"no models given for method {missing[0]}")
    problems = read_problems(problems_path)
    loaded = models if models is not None else load_method_models(models_dir, methods)
    for method in methods:
        n_max = getattr(loaded[method], "n_max", None)
        too_big = [p for p in problems if n_max is not None and p.n > n_max]
        if too_big:
            raise ValueError(f"{problems_path}: problem {too_big[0].name} has {too_big[0].n} objects, but the models "
                             f"of method {method} were trained for at most {n_max}")
    if models is None and config.workers == 1 and config.backend == "local":
        models = loaded  # one process: the models just loaded serve the run
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    meta = {"format": FORMAT, "models_dir": str(models_dir), "model_files": _model_files(models_dir),
            "problems": str(problems_path), "problems_sha256": _sha256(problems_path), "n_problems": len(problems),
            "config": config.defining(), "methods": methods, "versions": package_versions(), "started": started,
            "runs": [{"started": started, "methods": methods, "workers": config.workers, "backend": config.backend}]}
    out.mkdir(parents=True, exist_ok=True)
    lock = _lock(out)
    try:
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
            raise ValueError(f"{rows_path} holds a (problem, method) row twice; the file was edited")
        pairs = [(p, m) for p in problems for m in methods]
        tasks = [(p, m) for p, m in pairs if (p.name, m) not in done]
        run = _run_ray if config.backend == "ray" else _run_local
        with open(rows_path, "a") as f, tqdm(total=len(pairs), initial=len(pairs) - len(tasks), desc="evaluate",
                                             unit="row", disable=not config.progress, file=sys.stderr) as bar:
            if tasks:
                for row in run(tasks, str(models_dir), methods, models, config):
                    if row["outcome"] == ERROR_OUTCOME:
                        tqdm.write(f"warning: problem {row['problem']}, method {row['method']}: {row['error']}; "
                                   f"recorded as an error row (traceback in {rows_path}), the run goes on",
                                   file=sys.stderr)
                    f.write(json.dumps(row) + "\n")
                    f.flush()
                    bar.update()
        return rows_path
    finally:
        lock.close()


def strip_timings(row: dict) -> dict:
    """A row without its wall-clock fields (what must agree between runs and worker counts)."""
    return {k: v for k, v in row.items() if k not in TIMING_KEYS}


__all__ = ["ERROR_OUTCOME", "EvalConfig", "Evaluator", "OUTCOMES", "ROW_KEYS", "evaluate", "read_rows", "row_outcome",
           "strip_timings"]
