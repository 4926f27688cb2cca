"""The slow tail of planning: the kinematic check's shortcuts (remembered pick halves, stand-ins for the carried
boxes, the box test, grasps that cannot hold left out) and the stall cut find the plans that the search without
them found within its budget (the paper set's models, kinematics in the loop, fixed held-out problems)."""
from __future__ import annotations

from dataclasses import replace

import pytest

from tamp.app.problem import read_problem_set
from tamp.planning.config import PlanConfig
from tamp.planning.models import load_models, pretrained_dir
from tamp.planning.planners import plan
from tamp.sim.kinematic_checker import FeasibilityChecker
from tests.paths import DATA

pytestmark = [pytest.mark.sim, pytest.mark.slow]

# two problems of a strict set of seed 4242 (tests/data/tail-problems.jsonl): a Level-2 plan found after 86
# expansions, and a search that finds none within 400 (a stall cut of 300 ends it after about 360), on the 1 cm
# duplicate grid they were chosen with. The same comparison over whole problem sets: bench/planning_tail.py.
FINE = replace(PlanConfig(), search=replace(PlanConfig().search, resolution=0.01, max_expansions=400))
PROBLEMS = DATA / "tail-problems.jsonl"
NAMES = ("n4-k4-000", "n2-k3-005")


def planned(models, problem, cfg: PlanConfig, checker: FeasibilityChecker):
    """`bilevel`'s plan for `problem` under `cfg`, with the kinematic check `checker` from its initial scene."""
    checker.reset(problem.X_init)
    return plan("bilevel", models, problem.X_init, problem.X_goal, cfg.with_seed(problem.seed), kinematics=checker)


def test_the_search_finds_the_plans_it_found_without_its_shortcuts():
    problems = {p.name: p for p in read_problem_set(PROBLEMS)}
    models = load_models(pretrained_dir() / "paper")
    new = FeasibilityChecker()
    stalling = replace(FINE, search=replace(FINE.search, stall=300))
    old = FeasibilityChecker(world=new.world, shortcuts=False)
    left_out = 0
    for name in NAMES:
        problem = problems[name]
        before, stalled = planned(models, problem, FINE, old), planned(models, problem, stalling, new)
        # a search the stall cut did not end is the one without the cut (the cut only ends a search)
        cut = stalled.search is not None and stalled.search.status == "stalled"
        after = planned(models, problem, FINE, new) if cut else stalled
        assert before.plan == after.plan == stalled.plan, name
        assert before.level == after.level == (None if name == "n2-k3-005" else 2), name
        # grasps that cannot hold are never generated, so a state one of them reached first may be kept
        # through another action: the same plan, within a few expansions
        assert abs(after.search.expanded - before.search.expanded) <= 0.05 * before.search.expanded, name
        assert before.search.ungraspable == 0, name
        left_out += after.search.ungraspable
        if not before.solved:  # the stall cut ends it on its plateau
            assert before.search.status == after.search.status == "node_limit", name
            assert stalled.search.status == "stalled" and stalled.search.expanded < after.search.expanded, name
    assert left_out > 0  # cubes grasped off their centre: never predicted


# a 6-block problem of a tuning set (seed 5304; the `random` set, the default then) whose plan comes after the
# longest plateau of the tuning searches (350-400 expansions without progress, found after 411). That the cut ends
# the searches that find no plan, and loses none that the search to its budget finds: bench/planning_tail.py
# --objects 5,6 (and the cut's own rule: tests/tamp/planning/test_search.py).
GREEDY_PROBLEMS = DATA / "tail-problems-5-6.jsonl"


def test_from_5_blocks_the_greedy_stall_cut_lets_the_longest_plateau_through_to_its_plan():
    (problem,) = read_problem_set(GREEDY_PROBLEMS)
    result = planned(load_models(pretrained_dir() / "random"), problem, PlanConfig(), FeasibilityChecker())
    assert result.solved and result.level == 2 and result.search.status == "solved", result.reasons
    assert result.search.expanded > 400  # the plateau lay before the plan
    assert PlanConfig().search.greedy_stall == 800  # the cut this problem was chosen against
