"""Probabilistic symbolic planner (paper, Alg. 1 lines 5-7) and the deterministic baseline.

Plan in each of N sampled domains, record each unique plan (as pick-place action sequence) with the
number of domains that produced it, rank by normalised frequency (ties: shorter plan first, then
the action tuples), so the ranking is a deterministic function of (operators, problem, N, seed).

Backends:
- ``python``   in-process: one breadth-first search serves all N domains (`search.search_domains`),
               each domain getting its own first shortest plan in ground-action order; successors
               come from the lifted operators (`lifted.LiftedTask`), effects are drawn only for the
               operators the search meets (`sampling.DomainSet`). Fast path for Level 1.
- ``fd``       Fast Downward: one translation per problem of the *union* domain (each effect
               variant is an action), then the search binary alone on the SAS task restricted to
               each distinct domain (distinct on the operators that survived translation), run in
               parallel. Shortest plans with the default search (astar(lmcut())).
- ``fd-naive`` Fast Downward driver per sampled domain (write PDDL, translate, search): the baseline.
"""

from __future__ import annotations

import functools
import os
import time
from collections import Counter
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from symbolic import fast_downward as fd
from symbolic.grounding import check_problem, problem_states, steps_to_actions
from symbolic.lifted import LiftedTask
from symbolic.pddl import DomainWriter, problem_pddl
from symbolic.sampling import DomainSet, EffectSampler, dedup_choices
from symbolic.search import Decided, SearchOutcome, search_domains
from symbolic.structs import (
    OperatorSet,
    PlannerResult,
    PlannerStatus,
    PlanStep,
    ProbabilisticPlanResult,
    RankedPlan,
    SymbolicProblem,
)

BACKENDS = ("python", "fd", "fd-naive")


def _strip_variant(steps: list[PlanStep]) -> list[PlanStep]:
    return [(name.split("__e")[0], args) for name, args in steps]


class SymbolicPlanner:
    """Plans with one operator set. Reuse the instance across problems (the lifted task of each n is built once)."""

    def __init__(self, ops: OperatorSet, backend: str = "python", search: str = fd.DEFAULT_SEARCH,
                 time_limit: float = 10.0, scope: str = "subset", workers: int | None = None,
                 budget: int = 1_000_000):
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
        if scope not in ("subset", "exact"):
            raise ValueError(f"scope must be 'subset' or 'exact', got {scope!r}")
        if len(ops) == 0:
            raise ValueError("no operators to plan with")
        self.ops, self.backend, self.search, self.time_limit = ops, backend, search, time_limit
        self.scope, self.budget = scope, budget  # states generated per search (python backend)
        self.workers = workers or os.cpu_count() or 1
        self.sampler = EffectSampler(ops)  # cumulative effect tables, once per operator set
        self._tasks: dict[int, LiftedTask] = {}
        self._restricted: dict[tuple[int, tuple[int, ...]], LiftedTask] = {}  # (n, movable) -> task

    @functools.cached_property
    def writer(self) -> DomainWriter:
        """The domain's PDDL text, rendered when a Fast Downward backend first asks (the in-process search never)."""
        return DomainWriter(self.ops)

    # ---- helpers -------------------------------------------------------------------------------
    def task(self, n: int, movable: tuple[int, ...] | None = None) -> LiftedTask:
        """The lifted task of n-object scenes (built once per n: index tables, no grounding); with
        `movable`, its view whose actions pick only those objects (kept for the last 64 sets)."""
        if n not in self._tasks:
            self._tasks[n] = LiftedTask(self.ops, n, self.scope)
        if movable is None or len(movable) == n:
            return self._tasks[n]
        key = (n, tuple(movable))
        if key not in self._restricted:
            if len(self._restricted) >= 64:
                self._restricted.pop(next(iter(self._restricted)))
            self._restricted[key] = self._tasks[n].restricted(key[1])
        return self._restricted[key]

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
            start = time.perf_counter()
            out = self._search(problem, DomainSet.of_choices(self.ops, ch[None]), self.budget, start + self.time_limit)
            return self._result(self.task(problem.n, problem.movable), out, 0, time.perf_counter() - start)
        result = fd.run_fast_downward(self._domain_text(ch, problem.n), problem_pddl(self.ops, problem),
                                      self.search, self.time_limit)
        return result

    def plan_deterministic(self, problem: SymbolicProblem) -> PlannerResult:
        """The baseline: plan in the most-frequent-effect domain."""
        return self.plan(problem, None)

    # ---- probabilistic -------------------------------------------------------------------------
    def plan_probabilistic(self, problem: SymbolicProblem, n_domains: int = 100, seed: int = 0,
                           time_budget: float | None = None, budget: int | None = None,
                           decided: Callable[[list[RankedPlan]], bool] | None = None) -> ProbabilisticPlanResult:
        """Plan in N sampled domains and rank the plans by frequency. Python backend: with `budget`
        (states the shared search may generate; machine-independent, default the planner's) or
        `time_budget` (seconds), the domains without a plan when either runs out count as timed out; with
        `decided`, called between depth bounds with the head of the ranking no later plan can overtake
        (`symbolic.search`), the search stops when it returns True (a caller took one of those plans)."""
        check_problem(self.ops, problem)
        if self.backend == "python":
            return self._probabilistic_python(problem, n_domains, seed, time_budget, budget, decided)
        t0 = time.perf_counter()
        choices = self.sampler.choices(n_domains, seed)
        timings = {"sampling": time.perf_counter() - t0}
        if self.backend == "fd":
            per_domain, n_unique, n_searches = self._run_fd(problem, choices, timings)
        else:
            per_domain, n_unique, n_searches = self._run_fd_naive(problem, choices, timings)
        t0 = time.perf_counter()
        ranked = self._rank(per_domain, problem.n)
        timings["parsing"] = timings.get("parsing", 0.0) + time.perf_counter() - t0
        statuses = Counter(r.status.value for r in per_domain)
        return ProbabilisticPlanResult(ranked, n_domains, n_unique, n_searches, dict(statuses), timings)

    def _search(self, problem: SymbolicProblem, domains: DomainSet, budget: int,
                deadline: float, decided: Decided | None = None) -> SearchOutcome:
        """The one search for all `domains`, until `budget` generated states or `deadline` (time.perf_counter s)."""
        task = self.task(problem.n, problem.movable)
        init, goal = problem_states(problem)
        try:
            return search_domains(task, domains, init, goal, budget, deadline, problem.nonempty, decided)
        finally:  # expansions are not kept between problems (honest per-problem cost, bounded memory)
            task.clear_cache()

    def _probabilistic_python(self, problem: SymbolicProblem, n_domains: int, seed: int,
                              time_budget: float | None, budget: int | None,
                              decided: Callable[[list[RankedPlan]], bool] | None) -> ProbabilisticPlanResult:
        start = time.perf_counter()
        deadline = None if time_budget is None else start + time_budget
        deadline = min(deadline or np.inf, start + self.time_limit)
        domains = DomainSet.sampled(self.sampler, n_domains, seed)
        task = self.task(problem.n, problem.movable)  # the search's ground action numbers

        def head(out: SearchOutcome, searching: int) -> bool:
            """`decided` on the found plans with a count of at least the domains still searching: no plan to
            come outranks them (it would be longer, and a tie goes to the shorter)."""
            ranked = _ranked(_found(task, out, n_domains))
            ahead = [p for p in ranked if p.count >= searching.bit_count()]
            assert decided is not None  # head is passed only with it
            return bool(ahead) and decided(ahead)

        out = self._search(problem, domains, self.budget if budget is None else budget, deadline,
                           None if decided is None else head)
        searched = time.perf_counter() - start
        t0 = time.perf_counter()
        ranked = _ranked(_found(task, out, n_domains))
        statuses = Counter(s.value for s in out.status)
        timings = {"sampling": domains.seconds, "planner": searched - domains.seconds,
                   "backward": out.timings.get("backward", 0.0), "parsing": time.perf_counter() - t0}
        return ProbabilisticPlanResult(ranked, n_domains, None, 1, dict(statuses), timings, out.expanded,
                                       out.generated)

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
        return _ranked(found)

    def _result(self, task: LiftedTask, out: SearchOutcome, domain: int, seconds: float) -> PlannerResult:
        """The PlannerResult of one domain of a python search (over `task`), with its plan's symbolic states."""
        i = out.plan_of[domain]
        if i < 0:
            return PlannerResult(out.status[domain], None, out.message, seconds)
        return PlannerResult(out.status[domain], [task.step(g) for g in out.plans[i]], out.message, seconds,
                             states=list(out.states[i]))

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


def _found(task: LiftedTask, out: SearchOutcome, n_domains: int) -> dict[tuple, list]:
    """{actions: [steps, count, states]} of the plans a python search found so far; the first domain
    (in domain order) to produce a plan names its steps."""
    found: dict[tuple, list] = {}
    for k in range(n_domains):
        i = out.plan_of[k]
        if i < 0:
            continue
        key = tuple(task.action(g) for g in out.plans[i])
        if key in found:
            found[key][1] += 1
        else:
            found[key] = [tuple(task.step(g) for g in out.plans[i]), 1, out.states[i]]
    return found


def _ranked(found: dict[tuple, list]) -> list[RankedPlan]:
    """{actions: [steps, count, states]} -> plans by decreasing count, then length, then actions."""
    total = sum(v[1] for v in found.values())
    order = sorted(found.items(), key=lambda kv: (-kv[1][1], len(kv[0]), kv[0]))
    return [RankedPlan(k, s, c, c / total, None if states is None else tuple(states))
            for k, (s, c, states) in order]


def plan_probabilistic(ops: OperatorSet, problem: SymbolicProblem, n_domains: int = 100, seed: int = 0,
                       backend: str = "python", **kwargs) -> ProbabilisticPlanResult:
    """One-shot helper; prefer a `SymbolicPlanner` instance when planning many problems."""
    return SymbolicPlanner(ops, backend=backend, **kwargs).plan_probabilistic(problem, n_domains, seed)


def plan_deterministic(ops: OperatorSet, problem: SymbolicProblem, backend: str = "python",
                       **kwargs) -> PlannerResult:
    return SymbolicPlanner(ops, backend=backend, **kwargs).plan_deterministic(problem)
