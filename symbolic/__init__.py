"""Learned symbolic domains: bits -> lifted operators -> PDDL / PPDDL -> (probabilistic) plans.

Pure Python + numpy (Fast Downward is called as a subprocess). Main entry points:

    build_domain(unary_pre, rel_pre, actions, unary_post, rel_post, n_per_transition, out_dir)
    ops = load_domain(out_dir)
    planner = SymbolicPlanner(ops)                       # backend="python" | "fd" | "fd-naive"
    problem = make_problem(init_unary, init_rel, goal_unary, goal_rel)
    planner.plan_probabilistic(problem, n_domains=100, seed=0).plans   # ranked RankedPlan list
    planner.plan_deterministic(problem)                                 # PlannerResult

The python backend's parts: `LiftedTask` (successors per state without grounding), `DomainSet` and
`EffectSampler` (N sampled domains as bit masks, effects drawn on first use), `search_domains` (one
breadth-first search for all N domains); `symbolic.reference` keeps the plain per-domain version.
"""

from symbolic.build import build_domain, load_domain, make_problem, operators_file
from symbolic.dataset import make_dataset, split_dataset
from symbolic.fast_downward import (
                                    PlannerCrashed,
                                    PlannerError,
                                    PlannerTimeout,
                                    PlannerUnsolvable,
                                    raise_for_status,
                                    run_fast_downward,
)
from symbolic.grounding import apply_effect, replay, steps_to_actions
from symbolic.lifted import LiftedTask
from symbolic.operators import coverage, learn_operators, load_operators, save_operators, stats
from symbolic.pddl import DomainWriter, problem_pddl, write_domains
from symbolic.planner import SymbolicPlanner, plan_deterministic, plan_probabilistic
from symbolic.sampling import DomainSet, EffectSampler, dedup_choices, sample_choices, write_sampled_domains
from symbolic.search import search_domains
from symbolic.structs import (
                                    Action,
                                    Effect,
                                    Operator,
                                    OperatorSet,
                                    PlannerResult,
                                    PlannerStatus,
                                    ProbabilisticPlanResult,
                                    RankedPlan,
                                    SymbolicDataset,
                                    SymbolicProblem,
)

__all__ = [
    "Action", "DomainSet", "DomainWriter", "Effect", "EffectSampler", "LiftedTask", "Operator", "OperatorSet",
    "PlannerCrashed", "PlannerError", "PlannerResult", "PlannerStatus", "PlannerTimeout", "PlannerUnsolvable",
    "ProbabilisticPlanResult", "RankedPlan", "SymbolicDataset", "SymbolicPlanner", "SymbolicProblem",
    "apply_effect", "build_domain", "coverage", "dedup_choices", "learn_operators", "load_domain", "load_operators",
    "make_dataset", "make_problem", "plan_deterministic", "plan_probabilistic", "problem_pddl",
    "raise_for_status", "replay", "run_fast_downward", "operators_file", "sample_choices", "save_operators",
    "search_domains",
    "split_dataset", "stats", "steps_to_actions", "write_domains", "write_sampled_domains",
]
