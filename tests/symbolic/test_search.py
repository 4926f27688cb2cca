"""Level 1's symbolic search: one search for N domains gives each domain its own breadth-first plan;
lifted successors equal grounded ones; the paper set's domain's ranked plans stay what they were.

tests/data/level1_golden.json holds symbolic problems of the paper set's models (tamp/pretrained/paper/;
30: n = 2, 3, 4) with the
ranked plans Level 1 gave them. A change of the search, the sampler or the ranking that changes any of
them fails `test_ranked_plans_of_the_bundled_domain_are_unchanged`; if the change is meant, say so in
the closing note and rewrite the file:

    tamp problems --per-cell 2 --seed 1 --out /tmp/golden.jsonl
    .venv/bin/python -m tests.symbolic.test_search --write /tmp/golden.jsonl
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from symbolic import blocksworld as bw
from symbolic.atoms import pack_state, unpack_state
from symbolic.build import load_domain, make_problem
from symbolic.grounding import problem_states
from symbolic.lifted import LiftedTask
from symbolic.operators import learn_operators
from symbolic.planner import SymbolicPlanner
from symbolic.reference import GroundTask, bfs
from symbolic.sampling import DomainSet, EffectSampler
from symbolic.search import search_domains
from symbolic.structs import SymbolicProblem
from tests.paths import DATA, ROOT

GOLDEN = DATA / "level1_golden.json"
BUNDLED_DOMAIN = ROOT / "tamp" / "pretrained" / "paper" / "domain"


@pytest.fixture(scope="module")
def bundled():
    return load_domain(BUNDLED_DOMAIN)


@pytest.fixture(scope="module")
def golden():
    return json.loads(GOLDEN.read_text())


def _problem(entry: dict, ops) -> SymbolicProblem:
    n, d, K = entry["n"], ops.n_unary, ops.n_relations
    return make_problem(*unpack_state(int(entry["init"]), n, d, K), *unpack_state(int(entry["goal"]), n, d, K),
                        nonempty=entry["nonempty"])


def _ranked_plans(plans) -> list:
    return [[[list(a) for a in p.actions], p.count] for p in plans]


def _ranked(result) -> list:
    return _ranked_plans(result.plans)


def test_ranked_plans_of_the_bundled_domain_are_unchanged(bundled, golden):
    planner = SymbolicPlanner(bundled)
    for entry in golden["problems"]:
        out = planner.plan_probabilistic(_problem(entry, bundled), golden["n_domains"], entry["seed"],
                                         budget=golden["budget"])
        assert _ranked(out) == entry["ranked"], entry["name"]
        assert out.statuses == entry["statuses"], entry["name"]


def _check_against_one_bfs_per_domain(ops, problems, n_domains: int) -> int:
    planner = SymbolicPlanner(ops)
    compared = 0
    for problem, seed in problems:
        task, ground = planner.task(problem.n), GroundTask(ops, problem.n)
        init, goal = problem_states(problem)
        choices = planner.sampler.choices(n_domains, seed)
        out = search_domains(task, DomainSet.of_choices(ops, choices), init, goal, 10**6, None, problem.nonempty)
        for k in range(n_domains):
            status, plan, states, _ = bfs(ground, choices[k], init, goal, problem.nonempty)
            assert status is out.status[k]
            if plan is not None:
                i = out.plan_of[k]
                assert [(task.operator(g), task.binding(g)) for g in out.plans[i]] == plan
                assert list(out.states[i]) == states
            compared += 1
    return compared


def test_one_search_gives_every_domain_its_own_breadth_first_plan(bundled, golden):
    """Same plan (operators and bindings), same outcome, domain by domain, as a breadth-first search
    per domain over a grounded task: the blocks world (probabilistic, unsolvable goals included) and
    the bundled learned domain at n = 2, 3."""
    ops = learn_operators(bw.random_dataset(3000, (2, 3), seed=21, p_large=0.0))
    problems = [(bw.random_problem(3, k, seed=s, p_large=0.0)[0], s) for s, k in ((1, 1), (2, 2), (3, 3), (4, 4))]
    blocked = problems[3][0].goal_unary.copy()
    blocked[0, 2] = 1 - blocked[0, 2]  # block type never changes: no plan in any domain
    problems.append((SymbolicProblem(problems[3][0].init_unary, problems[3][0].init_rel, blocked,
                                     problems[3][0].goal_rel), 9))
    assert _check_against_one_bfs_per_domain(ops, problems, 30) == 150
    # more objects than any operator has parameters (operators bind to subsets)
    larger = [(bw.random_problem(n, k, seed=s, p_large=0.0)[0], s) for n, s, k in ((4, 2, 3), (4, 3, 4), (5, 2, 3),
                                                                                   (5, 3, 4), (5, 5, 5))]
    assert _check_against_one_bfs_per_domain(ops, larger, 20) == 100
    learned = [(_problem(e, bundled), e["seed"]) for e in golden["problems"] if e["n"] <= 3][:12]
    assert _check_against_one_bfs_per_domain(bundled, learned, 20) == 240


def test_lifted_successors_are_the_grounded_ones_in_ground_action_order(bundled, golden):
    for n in (2, 3):
        task, ground = LiftedTask(bundled, n), GroundTask(bundled, n)
        for entry in [e for e in golden["problems"] if e["n"] == n][:4]:
            for s in (int(entry["init"]), int(entry["goal"])):
                gs = ground.applicable(s)
                successors = list(dict.fromkeys(s ^ f for g in gs for f in ground.flips[g]))
                x = task.expand(s)
                assert x.successors == successors
                for t in successors[:10]:  # each successor's predecessors hold the state
                    if t != s:
                        assert s in task.predecessors(t)


def test_a_problem_with_movable_objects_plans_only_with_them_and_loses_no_plan_that_does():
    """`SymbolicProblem.movable`: every plan picks up only those objects, and a domain whose
    unrestricted breadth-first plan picks only them gets the same plan (fewer actions, same order)."""
    ops = learn_operators(bw.random_dataset(3000, (2, 3), seed=21, p_large=0.0))
    planner = SymbolicPlanner(ops)
    compared = 0
    for n, s, k in ((5, 2, 2), (5, 3, 3), (5, 5, 2), (4, 7, 3)):
        problem = bw.random_problem(n, k, seed=s, p_large=0.0)[0]
        full = planner.plan_probabilistic(problem, 20, s)
        picked = sorted({a[0] for p in full.plans for a in p.actions})
        assert picked and len(picked) < n
        focused = planner.plan_probabilistic(make_problem(problem.init_unary, problem.init_rel, problem.goal_unary,
                                                          problem.goal_rel, movable=picked), 20, s)
        assert _ranked(focused) == _ranked(full) and focused.statuses == full.statuses
        fewer = picked[1:]
        if fewer:
            narrow = planner.plan_probabilistic(make_problem(problem.init_unary, problem.init_rel, problem.goal_unary,
                                                             problem.goal_rel, movable=fewer), 20, s)
            assert all(a[0] in fewer for p in narrow.plans for a in p.actions)
            assert narrow.generated < full.generated
        compared += 1
    assert compared == 4
    with pytest.raises(ValueError, match="movable"):
        make_problem(problem.init_unary, problem.init_rel, problem.goal_unary, problem.goal_rel, movable=[n])


def test_sampled_domains_do_not_depend_on_n_and_masks_match_choices(bundled):
    sampler = EffectSampler(bundled)
    a, b = sampler.choices(100, seed=7), sampler.choices(30, seed=7)
    assert np.array_equal(a[:30], b)  # domain k is the same whatever N is
    assert not np.array_equal(a, sampler.choices(100, seed=8))
    domains = DomainSet.sampled(sampler, 100, seed=7)
    for o in sampler.probabilistic[:50].tolist():
        masks = domains.masks(o)
        assert sum(masks) == domains.full  # every domain takes exactly one effect
        for j, m in enumerate(masks):
            assert [k for k in range(100) if m >> k & 1] == np.flatnonzero(a[:, o] == j).tolist()


def test_a_search_stopped_on_its_decided_head_gives_the_full_rankings_plan(bundled, golden):
    """`decided`: each head offered is a prefix of the full search's ranking, with its final counts; taking the
    k-th plan of a head stops the search (the domains left STOPPED) with fewer states generated."""
    planner = SymbolicPlanner(bundled)
    stopped = 0
    for entry in golden["problems"]:
        problem = _problem(entry, bundled)
        full = planner.plan_probabilistic(problem, golden["n_domains"], entry["seed"])
        heads: list[list] = []

        def take_second(head, heads=heads) -> bool:
            heads.append(_ranked_plans(head))
            return len(head) >= 2

        early = planner.plan_probabilistic(problem, golden["n_domains"], entry["seed"], decided=take_second)
        for head in heads:
            assert head == _ranked(full)[:len(head)]
        if early.statuses.get("stopped", 0):
            stopped += 1
            assert len(heads[-1]) >= 2 and early.generated < full.generated
            assert _ranked(early)[:2] == _ranked(full)[:2]
            assert sum(early.statuses.values()) == golden["n_domains"]
        else:
            assert _ranked(early) == _ranked(full) and early.statuses == full.statuses
    assert stopped >= 3


def test_the_budget_decides_and_no_state_is_kept(bundled, golden):
    planner = SymbolicPlanner(bundled)
    entry = max(golden["problems"], key=lambda e: max((len(p[0]) for p in e["ranked"]), default=0))
    problem = _problem(entry, bundled)
    runs = [planner.plan_probabilistic(problem, 100, entry["seed"], budget=3) for _ in range(2)]
    assert runs[0].statuses == runs[1].statuses and runs[0].statuses.get("timeout", 0) > 0
    assert _ranked(runs[0]) == _ranked(runs[1])
    assert planner.task(problem.n).cached_states == 0


def _write(problems_file: str) -> None:
    """Regenerate the golden file from a problem set with the paper set's models (needs torch)."""
    import torch

    from tamp.app.problem import read_problem_set
    from tamp.planning.config import PlanConfig
    from tamp.planning.level1 import symbolic_problem
    from tamp.planning.models import load_models, pretrained_dir

    torch.set_num_threads(1)
    models = load_models(pretrained_dir() / "paper")
    cfg = PlanConfig()
    planner = SymbolicPlanner(models.domain)
    entries = []
    for p in read_problem_set(problems_file):
        sp = symbolic_problem(models, p.X_init, p.X_goal, cfg)
        out = planner.plan_probabilistic(sp, cfg.level1.n_domains, p.seed, budget=cfg.level1.budget)
        entries.append({"name": p.name, "n": sp.n, "seed": p.seed, "nonempty": sp.nonempty,
                        "init": str(pack_state(sp.init_unary, sp.init_rel)),
                        "goal": str(pack_state(sp.goal_unary, sp.goal_rel)),
                        "ranked": _ranked(out), "statuses": out.statuses})
    GOLDEN.write_text(json.dumps({"source": f"{Path(problems_file).name} with the bundled models",
                                  "n_domains": cfg.level1.n_domains, "budget": cfg.level1.budget,
                                  "problems": entries}, indent=0) + "\n")
    print(f"wrote {len(entries)} problems to {GOLDEN}")


if __name__ == "__main__":
    if len(sys.argv) != 3 or sys.argv[1] != "--write":
        sys.exit("usage: python -m tests.symbolic.test_search --write PROBLEMS.jsonl")
    _write(sys.argv[2])
