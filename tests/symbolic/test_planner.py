"""Planner outcomes, plan validity by replay, backend agreement, ranking stability, bad problems."""

from __future__ import annotations

import pytest

from symbolic import blocksworld as bw
from symbolic import fast_downward as fd
from symbolic.build import make_problem
from symbolic.grounding import replay, steps_to_actions
from symbolic.operators import learn_operators
from symbolic.pddl import problem_pddl
from symbolic.planner import SymbolicPlanner
from symbolic.sampling import sample_choices
from symbolic.structs import PlannerStatus, SymbolicProblem


@pytest.fixture(scope="module")
def ops():
    return learn_operators(bw.random_dataset(3000, (2, 3), seed=21, p_large=0.0))


@pytest.fixture(scope="module")
def problems():
    return [bw.random_problem(3, k, seed=s, p_large=0.0)[0] for s, k in ((1, 1), (2, 2), (3, 3), (4, 2))]


def _unsolvable(problem: SymbolicProblem) -> SymbolicProblem:
    goal_u = problem.goal_unary.copy()
    goal_u[0, 2] = 1 - goal_u[0, 2]  # block type never changes
    return SymbolicProblem(problem.init_unary, problem.init_rel, goal_u, problem.goal_rel)


def test_python_plans_replay_in_their_domain(ops, problems):
    planner = SymbolicPlanner(ops, backend="python")
    choices = sample_choices(ops, 10, seed=0)
    solved = 0
    for problem in problems:
        for c in choices:
            r = planner.plan(problem, c)
            assert r.status in (PlannerStatus.SOLVED, PlannerStatus.UNSOLVABLE)
            if r.solved:
                solved += 1
                assert replay(ops, problem, r.plan, c) == (True, "ok")
                if r.plan:  # and, in general, not in other domains: replay really checks effects
                    assert replay(ops, problem, r.plan[:-1], c)[0] is False
    assert solved >= 20


@pytest.mark.slow
def test_fd_and_python_agree_on_outcome_and_plan_length(ops, problems):
    py = SymbolicPlanner(ops, backend="python")
    fdp = SymbolicPlanner(ops, backend="fd-naive", search="astar(lmcut())", time_limit=20)
    choices = sample_choices(ops, 2, seed=3)
    for problem in problems[1:3] + [_unsolvable(problems[0])]:
        for c in choices:
            a, b = py.plan(problem, c), fdp.plan(problem, c)
            assert a.status == b.status, (a.message, b.message)
            if b.solved:
                assert len(a.plan) == len(b.plan)
                assert replay(ops, problem, b.plan, c) == (True, "ok")


def test_probabilistic_ranking_is_stable_and_normalised(ops, problems):
    planner = SymbolicPlanner(ops, backend="python")
    problem = problems[2]
    r1 = planner.plan_probabilistic(problem, n_domains=60, seed=4)
    r2 = SymbolicPlanner(ops, backend="python").plan_probabilistic(problem, n_domains=60, seed=4)
    assert [(p.actions, p.count) for p in r1.plans] == [(p.actions, p.count) for p in r2.plans]
    assert r1.plans, "no plan found"
    assert sum(p.count for p in r1.plans) == r1.statuses.get("solved", 0)
    assert sum(p.probability for p in r1.plans) == pytest.approx(1.0)
    keys = [(-p.count, len(p.actions), p.actions) for p in r1.plans]
    assert keys == sorted(keys)
    choices = sample_choices(ops, 60, seed=4)
    for p in r1.plans:  # every ranked plan is valid in (at least) one of the sampled domains
        assert any(replay(ops, problem, list(p.steps), c)[0] for c in choices)
        assert list(p.actions) == steps_to_actions(ops, list(p.steps), problem.n)
    # reusing searches must not change the answer: compare with one search per domain
    per_domain = {}
    for c in choices:
        res = planner.plan(problem, c)
        if res.solved:
            key = tuple(steps_to_actions(ops, res.plan, problem.n))
            per_domain[key] = per_domain.get(key, 0) + 1
    assert {p.actions: p.count for p in r1.plans} == per_domain
    assert r1.n_searches == 1 and r1.expanded > 0  # one search serves all 60 domains


def test_fd_backend_gives_valid_ranked_plans(ops, problems):
    problem = problems[1]
    res = SymbolicPlanner(ops, backend="fd", time_limit=20).plan_probabilistic(problem, n_domains=8, seed=1)
    assert res.statuses == {"solved": 8}
    py = SymbolicPlanner(ops, backend="python").plan_probabilistic(problem, n_domains=8, seed=1)
    assert {len(p.actions) for p in res.plans} == {len(p.actions) for p in py.plans}
    choices = sample_choices(ops, 8, seed=1)
    for p in res.plans:
        assert any(replay(ops, problem, list(p.steps), c)[0] for c in choices)


@pytest.mark.slow
def test_planner_outcomes_are_distinguishable(ops, problems):
    py = SymbolicPlanner(ops, backend="python", budget=1)
    assert py.plan(problems[2]).status is PlannerStatus.TIMEOUT  # needs three steps
    py = SymbolicPlanner(ops, backend="python")
    assert py.plan(_unsolvable(problems[3])).status is PlannerStatus.UNSOLVABLE
    assert py.plan(problems[3]).status is PlannerStatus.SOLVED
    res = py.plan_probabilistic(_unsolvable(problems[3]), n_domains=5)
    assert res.plans == [] and res.statuses == {"unsolvable": 5}

    bad = fd.run_fast_downward(*_counter(8), search="nonsense()", time_limit=20)
    assert bad.status is PlannerStatus.CRASHED and "nonsense" in bad.message
    with pytest.raises(fd.PlannerCrashed):
        fd.raise_for_status(bad)
    slow = fd.run_fast_downward(*_counter(30), search="astar(blind())", time_limit=3)
    assert slow.status is PlannerStatus.TIMEOUT
    with pytest.raises(fd.PlannerTimeout):
        fd.raise_for_status(slow)
    unsolvable = fd.run_fast_downward(*_counter(4, reachable=False), time_limit=20)
    assert unsolvable.status is PlannerStatus.UNSOLVABLE
    with pytest.raises(fd.PlannerUnsolvable):
        fd.raise_for_status(unsolvable)
    ok = fd.raise_for_status(fd.run_fast_downward(*_counter(3), time_limit=20))
    assert ok.status is PlannerStatus.SOLVED and len(ok.plan) == 7  # 2^3 - 1 increments


def test_parallel_fd_calls_keep_their_own_plans(ops, problems):
    from concurrent.futures import ThreadPoolExecutor

    tasks = [_counter(k) for k in (1, 2, 3, 4)] * 2
    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(lambda t: fd.run_fast_downward(*t, time_limit=20), tasks))
    assert [len(r.plan) for r in results] == [1, 3, 7, 15] * 2


def test_bad_problems_give_clear_errors(ops, problems):
    p = problems[0]
    with pytest.raises(ValueError, match="unknown object 'o7'"):
        replay(ops, p, [(ops.operators[0].name, ("o7",) * ops.operators[0].arity)])
    with pytest.raises(ValueError, match="unknown object"):
        steps_to_actions(ops, [(ops.operators[0].name, ("o0", "o3", "o1")[: ops.operators[0].arity][::-1])
                               if ops.operators[0].arity > 1 else (ops.operators[0].name, ("o3",))], 3)
    with pytest.raises(ValueError, match="unknown operator"):
        steps_to_actions(ops, [("pp9999_g0_r0", ("o0",))], 3)
    with pytest.raises(ValueError, match="relation bits must have shape"):
        make_problem(p.init_unary, p.init_rel[:, :2], p.goal_unary, p.goal_rel)
    with pytest.raises(ValueError, match="goal has 2 objects"):
        make_problem(p.init_unary, p.init_rel, p.goal_unary[:2], p.goal_rel[:, :2, :2])
    with pytest.raises(ValueError, match="expected 3 unary bits"):
        problem_pddl(ops, SymbolicProblem(p.init_unary[:, :2], p.init_rel, p.goal_unary[:, :2], p.goal_rel))
    with pytest.raises(ValueError, match="0 or 1"):
        SymbolicPlanner(ops).plan(SymbolicProblem(p.init_unary * 3, p.init_rel, p.goal_unary, p.goal_rel))
    with pytest.raises(ValueError, match="backend"):
        SymbolicPlanner(ops, backend="magic")


# A binary counter in plain STRIPS: inc{b} sets bit b when all lower bits are one and resets them.
# Plans have length 2^k - 1; blind search visits up to 2^k states.
def _counter(k: int, reachable: bool = True) -> tuple[str, str]:
    acts = []
    for b in range(k):
        lower = " ".join(f"(one b{j})" for j in range(b))
        resets = " ".join(f"(zero b{j}) (not (one b{j}))" for j in range(b))
        acts.append(f"(:action inc{b} :parameters () :precondition (and (zero b{b}) {lower})"
                    f" :effect (and (one b{b}) (not (zero b{b})) {resets}))")
    bits = " ".join(f"b{j}" for j in range(k))
    domain = (f"(define (domain counter) (:requirements :strips) (:constants {bits})"
              " (:predicates (one ?b) (zero ?b) (stuck))\n" + "\n".join(acts) + ")\n")
    goal = " ".join(f"(one b{j})" for j in range(k)) + ("" if reachable else " (stuck)")
    init = " ".join(f"(zero b{j})" for j in range(k))
    return domain, f"(define (problem c{k}) (:domain counter) (:init {init}) (:goal (and {goal})))\n"


def test_level1_time_budget_bounds_probabilistic_planning(ops, problems):
    problem = problems[2]
    unbounded = SymbolicPlanner(ops, backend="python").plan_probabilistic(problem, n_domains=60, seed=4)
    same = SymbolicPlanner(ops, backend="python").plan_probabilistic(problem, n_domains=60, seed=4, time_budget=60.0)
    assert [(p.actions, p.count) for p in same.plans] == [(p.actions, p.count) for p in unbounded.plans]
    spent = SymbolicPlanner(ops, backend="python").plan_probabilistic(problem, n_domains=60, seed=4, time_budget=0.0)
    assert spent.statuses == {"timeout": 60} and spent.plans == []
    # the planner's time_limit bounds every python search, one deterministic domain's too
    assert SymbolicPlanner(ops, backend="python").plan_deterministic(problem).solved
    late = SymbolicPlanner(ops, backend="python", time_limit=1e-9).plan_deterministic(problem)
    assert late.status.value == "timeout" and not late.solved


def test_level1_budget_is_shared_by_all_domains_and_deterministic(ops, problems):
    problem = problems[2]
    unbounded = SymbolicPlanner(ops, backend="python").plan_probabilistic(problem, n_domains=60, seed=4)
    ample = SymbolicPlanner(ops, backend="python").plan_probabilistic(problem, n_domains=60, seed=4,
                                                                     budget=10**9)
    assert [(p.actions, p.count) for p in ample.plans] == [(p.actions, p.count) for p in unbounded.plans]
    spent = SymbolicPlanner(ops, backend="python").plan_probabilistic(problem, n_domains=60, seed=4,
                                                                     budget=0)
    assert spent.statuses == {"timeout": 60} and spent.plans == []
    tight = [SymbolicPlanner(ops, backend="python").plan_probabilistic(problem, n_domains=60, seed=4,
                                                                      budget=3) for _ in range(2)]
    assert tight[0].statuses == tight[1].statuses and tight[0].statuses.get("timeout", 0) > 0
    assert [(p.actions, p.count) for p in tight[0].plans] == [(p.actions, p.count) for p in tight[1].plans]


def test_no_search_state_is_kept_between_problems(ops, problems):
    """A long evaluation plans thousands of problems with one planner: the states its searches cached
    (GBs at 4 objects with a paper-scale domain) must not pile up from one problem to the next."""
    planner = SymbolicPlanner(ops)
    for problem in problems[:3] + [_unsolvable(problems[0])]:
        task = planner.task(problem.n)
        planner.plan_deterministic(problem)
        assert task.cached_states == 0
        planner.plan_probabilistic(problem, n_domains=10, seed=0)
        assert task.cached_states == 0
