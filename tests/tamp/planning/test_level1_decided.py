"""Level 1 verifies the ranking's decided head while the symbolic search runs: it takes the plan that
Algorithm 1 takes after the full search, and the search stops there (the bundled models, four problems of
the tuning set strict-n2-4-s69 on which it stops: tests/data/level1-decided.jsonl)."""
from __future__ import annotations

from dataclasses import replace

import pytest

from tamp.app.problem import read_problem_set
from tamp.planning.config import KinematicsConfig, Level1Config, PlanConfig
from tamp.planning.level1 import Verifier
from tamp.planning.models import load_models, pretrained_dir
from tamp.planning.planners import plan
from tests.paths import DATA

# the budget these problems were chosen with: some domains search on after the plan taken is decided
CFG = replace(PlanConfig(), kinematics=KinematicsConfig(feasibility=False), level1=Level1Config(budget=100_000))


@pytest.fixture(scope="module")
def models():
    return load_models(pretrained_dir())


def test_level1_takes_the_full_rankings_first_verified_plan_and_stops_the_search(models, monkeypatch):
    problems = read_problem_set(DATA / "level1-decided.jsonl")
    early = [plan("bilevel", models, p.X_init, p.X_goal, CFG) for p in problems]
    monkeypatch.setattr(Verifier, "check_decided", lambda self, head: False)  # verify after the full search
    full = [plan("bilevel", models, p.X_init, p.X_goal, CFG) for p in problems]
    for p, a, b in zip(problems, early, full):
        assert a.level == b.level == 1 and a.plan == b.plan, p.name
        assert a.candidates[0].actions == b.candidates[0].actions, p.name
        assert a.symbolic_stats["outcomes"].get("stopped", 0) > 0, p.name
        assert "stopped" not in b.symbolic_stats["outcomes"], p.name
        assert a.symbolic_stats["generated"] < b.symbolic_stats["generated"], p.name
