"""Probabilistic symbolic planner (paper, Alg. 1 lines 5-7) and the deterministic baseline.

Plan in each of N sampled domains, record each unique plan (as pick-place action sequence) with the
number of domains that produced it, rank by normalised frequency (ties: shorter plan first, then
the action tuples), so the ranking is a deterministic function of (operators, problem, N, seed).

Backends:
- ``python``   in-process search over the grounded task (`search.py`): by default the first shortest
               plan of a breadth-first search, or with objective="likely" the most probable plan
               (uniform-cost search, cost 1 - ln p(effect) per step). Ground actions
               are built once per (operator set, n) and a search is reused for every domain that
               agrees with it on the operators it touched. Fast path for Level 1.
- ``fd``       Fast Downward: one translation per problem of the *union* domain (each effect
               variant is an action), then the search binary alone on the SAS task restricted to
               each distinct domain (distinct on the operators that survived translation), run in
               parallel. Shortest plans with the default search (astar(lmcut())).
- ``fd-naive`` Fast Downward driver per sampled domain (write PDDL, translate, search): the baseline.
"""

from __future__ import annotations

import itertools
import os
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from symbolic import fast_downward as fd
from symbolic.grounding import GroundTask, check_problem, problem_states, steps_to_actions
from symbolic.pddl import DomainWriter, effect_probabilities, problem_pddl
from symbolic.sampling import dedup_choices, sample_choices
from symbolic.search import action_costs, bfs, most_likely
from symbolic.structs import (
    Action,
    OperatorSet,
    PlannerResult,
    PlannerStatus,
    PlanStep,
    ProbabilisticPlanResult,
    RankedPlan,
    SymbolicProblem,
)

BACKENDS = ("python", "fd", "fd-naive")
# python backend: "shortest" = breadth-first search, the first shortest plan in ground-action order
# (as Fast Downward's optimal searches); "likely" = most probable plan (cost 1 - ln p per step,
# `search.most_likely`). On learned Drake-world domains "likely" did not help: 1 instead of 4 of 60
# unverified symbolic plans succeeded (the symbols, not the choice among plans, limit them).
OBJECTIVES = ("likely", "shortest")


def _strip_variant(steps: list[PlanStep]) -> list[PlanStep]:
    return [(name.split("__e")[0], args) for name, args in steps]


class SymbolicPlanner:
    """Plans with one operator set. Reuse the instance across problems (ground tasks are cached)."""

    def __init__(self, ops: OperatorSet, backend: str = "python", search: str = fd.DEFAULT_SEARCH,
                 time_limit: float = 10.0, scope: str = "subset", workers: int | None = None,
                 max_expansions: int = 200_000, objective: str = "shortest"):
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
        if objective not in OBJECTIVES:
            raise ValueError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
        self.objective = objective
        self._costs = action_costs([effect_probabilities(op) for op in ops.operators])
        if scope not in ("subset", "exact"):
            raise ValueError(f"scope must be 'subset' or 'exact', got {scope!r}")
        if len(ops) == 0:
            raise ValueError("no operators to plan with")
        self.ops, self.backend, self.search, self.time_limit = ops, backend, search, time_limit
        self.scope, self.max_expansions = scope, max_expansions
        self.workers = workers or os.cpu_count() or 1
        self.writer = DomainWriter(ops)
        self._tasks: dict[int, GroundTask] = {}

    # ---- helpers -------------------------------------------------------------------------------
    def ground(self, n: int) -> GroundTask:
        if n not in self._tasks:
            self._tasks[n] = GroundTask(self.ops, n, self.scope)
        return self._tasks[n]

    def _allowed(self, n: int) -> np.ndarray:
        ar = np.array([op.arity for op in self.ops.operators])
        return ar == n if self.scope == "exact" else ar <= n

    def _domain_text(self, choice: np.ndarray, n: int) -> str:
        allowed = self._allowed(n)
        if allowed.all():
            return self.writer.pddl(choice)
        sub = OperatorSet([op for op, a in zip(self.ops.operators, allowed) if a], self.ops.n_unary,
                          self.ops.n_relations)
        return DomainWriter(sub).pddl(np.asarray(choice)[allowed])

    # ---- one deterministic domain --------------------------------------------------------------
    def plan(self, problem: SymbolicProblem, choice: np.ndarray | None = None) -> PlannerResult:
        """Plan in one deterministic domain (effect choice per operator; default most frequent)."""
        check_problem(self.ops, problem)
        ch = np.zeros(len(self.ops), np.int64) if choice is None else np.asarray(choice)
        if self.backend == "python":
            task = self.ground(problem.n)
            init, goal = problem_states(problem)
            start = time.perf_counter()
            task.clear_cache()  # per problem, as in `_run_python`; and freed after it (it can hold GBs)
            try:
                out = self._search(task, ch, init, goal, self.max_expansions, self.time_limit, problem.nonempty)
                return self._result(task, ch, init, out, time.perf_counter() - start)
            finally:
                task.clear_cache()
        result = fd.run_fast_downward(self._domain_text(ch, problem.n), problem_pddl(self.ops, problem),
                                      self.search, self.time_limit)
        return result

    def plan_deterministic(self, problem: SymbolicProblem) -> PlannerResult:
        """The baseline: plan in the most-frequent-effect domain."""
        return self.plan(problem, None)

    # ---- probabilistic -------------------------------------------------------------------------
    def plan_probabilistic(self, problem: SymbolicProblem, n_domains: int = 100, seed: int = 0,
                           min_prob: float = 0.0, time_budget: float | None = None,
                           expansion_budget: int | None = None) -> ProbabilisticPlanResult:
        """Plan in N sampled domains and rank the plans by frequency. Python backend: with
        `expansion_budget` (search expansions over all domains; machine-independent) or `time_budget`
        (seconds), the domains not searched when either runs out count as timed out."""
        check_problem(self.ops, problem)
        deadline = None if time_budget is None else time.perf_counter() + time_budget
        t0 = time.perf_counter()
        choices = sample_choices(self.ops, n_domains, seed, min_prob)
        timings = {"sampling": time.perf_counter() - t0}
        if self.backend == "python":
            try:
                per_domain, n_unique, n_searches = self._run_python(problem, choices, timings, deadline,
                                                                    expansion_budget)
            finally:  # the state cache, shared by the N domains' searches, is not kept between problems
                self.ground(problem.n).clear_cache()
        elif self.backend == "fd":
            per_domain, n_unique, n_searches = self._run_fd(problem, choices, timings)
        else:
            per_domain, n_unique, n_searches = self._run_fd_naive(problem, choices, timings)
        t0 = time.perf_counter()
        ranked = self._rank(per_domain, problem.n)
        timings["parsing"] = timings.get("parsing", 0.0) + time.perf_counter() - t0
        statuses = Counter(r.status.value for r in per_domain)
        return ProbabilisticPlanResult(ranked, n_domains, n_unique, n_searches, dict(statuses), timings)

    def _rank(self, per_domain: list[PlannerResult], n: int) -> list[RankedPlan]:
        found: dict[tuple, list] = {}
        parsed: dict[int, tuple] = {}  # reused searches share one result object: parse it once
        for r in per_domain:  # domain order: the first domain to produce a plan names its steps
            if r.status is not PlannerStatus.SOLVED:
                continue
            if id(r) not in parsed:
                assert r.plan is not None  # solved
                steps = tuple(_strip_variant(r.plan))
                parsed[id(r)] = (steps, tuple(steps_to_actions(self.ops, list(steps), n)))
            steps, key = parsed[id(r)]
            if key in found:
                found[key][1] += 1
            else:
                found[key] = [steps, 1, None if r.states is None else tuple(r.states)]
        total = sum(v[1] for v in found.values())
        order = sorted(found.items(), key=lambda kv: (-kv[1][1], len(kv[0]), kv[0]))
        return [RankedPlan(k, s, c, c / total, states) for k, (s, c, states) in order]

    def _run_python(self, problem, choices, timings, deadline: float | None = None,
                    expansion_budget: int | None = None):
        t0 = time.perf_counter()
        task = self.ground(problem.n)
        task.clear_cache()  # no state cache carried over between problems (honest per-problem cost)
        init, goal = problem_states(problem)
        timings["grounding"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        reps, counts, group = dedup_choices(choices[:, self._probabilistic_columns()])
        timings["sampling"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        memo: list[tuple[np.ndarray, np.ndarray, PlannerResult]] = []
        results: list[PlannerResult] = []
        out_of_time = PlannerResult(PlannerStatus.TIMEOUT, None, "Level-1 time budget used up")
        out_of_expansions = PlannerResult(PlannerStatus.TIMEOUT, None, "Level-1 expansion budget used up")
        left = self.max_expansions * len(reps) if expansion_budget is None else expansion_budget
        for k in reps:
            c = choices[k]
            hit = next((res for touched, vals, res in memo if np.array_equal(c[touched], vals)), None)
            if hit is None and deadline is not None and time.perf_counter() > deadline:
                hit = out_of_time
            if hit is None and left <= 0:
                hit = out_of_expansions
            if hit is None:
                start = time.perf_counter()
                limit = self.time_limit if deadline is None else \
                    max(0.0, min(self.time_limit, deadline - time.perf_counter()))
                out = self._search(task, c, init, goal, min(self.max_expansions, left), limit, problem.nonempty)
                left -= out.expanded
                hit = self._result(task, c, init, out, time.perf_counter() - start)
                if out.status is not PlannerStatus.TIMEOUT:
                    memo.append((out.touched, c[out.touched], hit))
            results.append(hit)
        timings["planner"] = time.perf_counter() - t0
        return [results[g] for g in group], len(reps), len(memo)

    def _search(self, task: GroundTask, choice, init: int, goal: int, max_expansions: int,
                time_limit: float | None, nonempty: bool):
        if self.objective == "shortest":
            return bfs(task, choice, init, goal, max_expansions, time_limit, nonempty)
        return most_likely(task, choice, init, goal, self._costs, max_expansions, time_limit, nonempty)

    @staticmethod
    def _result(task: GroundTask, choice: np.ndarray, init: int, out, seconds: float) -> PlannerResult:
        """A PlannerResult of the python search, with the plan's ground actions and symbolic states."""
        if out.plan is None:
            return PlannerResult(out.status, None, out.message, seconds)
        states = [init]
        for g in out.plan:
            states.append(states[-1] ^ task.flips[g][int(choice[task.op_index[g]])])
        return PlannerResult(out.status, [task.step(g) for g in out.plan], out.message, seconds,
                             ground=list(out.plan), states=states)

    def skeleton_options(self, n: int, states: tuple[int, ...]) -> list[list[Action]]:
        """Per step of a plan through the symbolic `states` (a RankedPlan's), every ground action
        applicable in that state one of whose learned effects leads to the next state: the plan's
        skeleton, with the choices the symbols cannot tell apart (typically the grasp and release
        offsets, or which of two symbolically alike blocks is used)."""
        task = self.ground(n)
        options = []
        for s, t in zip(states[:-1], states[1:]):
            gs, _ = task.applicable(s)
            options.append(list(dict.fromkeys(task.action(g) for g in gs if any(s ^ f == t for f in task.flips[g]))))
        return options

    def alternatives(self, n: int, actions: tuple[Action, ...], states: tuple[int, ...] | None,
                     limit: int = 64) -> list[tuple[Action, ...]]:
        """Other plans through the same symbolic `states` as `actions`, at most `limit`, in the
        order of `itertools.product` over `skeleton_options` (the last step varies fastest)."""
        if states is None or not actions or limit < 1:
            return []
        out = []
        for combo in itertools.product(*self.skeleton_options(n, states)):
            if combo != tuple(actions):
                out.append(combo)
                if len(out) == limit:
                    break
        return out

    def _probabilistic_columns(self) -> np.ndarray:
        return np.flatnonzero([len(op.effects) > 1 for op in self.ops.operators])

    def _run_fd(self, problem, choices, timings):
        t0 = time.perf_counter()
        allowed = self._allowed(problem.n)
        keep_ops = np.flatnonzero(allowed)
        sub = OperatorSet([self.ops.operators[i] for i in keep_ops], self.ops.n_unary, self.ops.n_relations)
        domain = (self.writer if allowed.all() else DomainWriter(sub)).union()
        prob = problem_pddl(self.ops, problem)
        timings["writing"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        try:
            sas = fd.SasTask(fd.translate(domain, prob, self.time_limit))
        except fd.PlannerError as e:  # e.g. the translator proves the task unsolvable
            timings["planner"] = time.perf_counter() - t0
            return [e.result] * len(choices), 1, 1
        timings["translate"] = time.perf_counter() - t0
        names = self.ops.by_name()
        variant = []
        for line in sas.names:
            base, _, effect = line.split()[0].partition("__e")
            variant.append((names[base], int(effect)))
        var_op = np.array([v[0] for v in variant], np.int64)
        var_eff = np.array([v[1] for v in variant], np.int64)
        relevant = np.unique(var_op) if variant else np.empty(0, np.int64)
        t1 = time.perf_counter()
        reps, counts, group = dedup_choices(choices, relevant)
        timings["sampling"] += time.perf_counter() - t1
        t1 = time.perf_counter()
        tasks = [sas.restrict(choices[k][var_op] == var_eff) for k in reps]
        with ThreadPoolExecutor(max_workers=self.workers) as pool:
            results = list(pool.map(lambda s: fd.run_search(s, self.search, self.time_limit), tasks))
        timings["planner"] = timings.pop("translate") + time.perf_counter() - t1
        return [results[g] for g in group], len(reps), len(reps) + 1

    def _run_fd_naive(self, problem, choices, timings):
        prob = problem_pddl(self.ops, problem)
        t0 = time.perf_counter()
        domains = [self._domain_text(c, problem.n) for c in choices]
        timings["writing"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        results = [fd.run_fast_downward(d, prob, self.search, self.time_limit) for d in domains]
        timings["planner"] = time.perf_counter() - t0
        return results, len({d for d in domains}), len(domains)


def plan_probabilistic(ops: OperatorSet, problem: SymbolicProblem, n_domains: int = 100, seed: int = 0,
                       backend: str = "python", **kwargs) -> ProbabilisticPlanResult:
    """One-shot helper; prefer a `SymbolicPlanner` instance when planning many problems."""
    return SymbolicPlanner(ops, backend=backend, **kwargs).plan_probabilistic(problem, n_domains, seed)


def plan_deterministic(ops: OperatorSet, problem: SymbolicProblem, backend: str = "python",
                       **kwargs) -> PlannerResult:
    return SymbolicPlanner(ops, backend=backend, **kwargs).plan_deterministic(problem)
