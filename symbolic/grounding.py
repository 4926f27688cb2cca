"""Symbolic problems and plans: checks, packed init/goal states, plan steps -> actions, and replay.

A ground action binds an operator's parameters to distinct scene objects (successors are generated
lifted, per state: `lifted.py`). `replay` applies plan steps with array operations, independently of
the packed search, so that tests can check the search's plans.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from symbolic.atoms import check_bits, object_index, pack_state
from symbolic.structs import Action, Effect, OperatorSet, PlanStep, SymbolicProblem


def check_problem(ops: OperatorSet, problem: SymbolicProblem) -> None:
    """ValueError unless init and goal bits are valid states of the same scene for these operators."""
    check_bits(problem.init_unary, problem.init_rel, "init", ops.n_unary, ops.n_relations)
    check_bits(problem.goal_unary, problem.goal_rel, "goal", ops.n_unary, ops.n_relations)
    if np.shape(problem.goal_unary)[0] != np.shape(problem.init_unary)[0]:
        raise ValueError("init and goal must describe the same objects")


def problem_states(problem: SymbolicProblem) -> tuple[int, int]:
    return (pack_state(problem.init_unary, problem.init_rel), pack_state(problem.goal_unary, problem.goal_rel))


def steps_to_actions(ops: OperatorSet, steps: list[PlanStep], n: int) -> list[Action]:
    """Plan steps (operator name, object names) -> pick-place 4-tuples; ValueError on unknown names."""
    names = ops.by_name()
    actions = []
    for name, args in steps:
        base = name.split("__e")[0]
        if base not in names:
            raise ValueError(f"unknown operator {name!r} in plan")
        op = ops.operators[names[base]]
        if len(args) != op.arity:
            raise ValueError(f"{name} takes {op.arity} objects, got {len(args)}")
        actions.append(op.action(tuple(object_index(a, n) for a in args)))
    return actions


def apply_effect(unary: np.ndarray, rel: np.ndarray, effect: Effect,
                 binding: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """The state after `effect` of an operator whose parameters are bound to the objects `binding`
    (new arrays; the precondition is the caller's to check)."""
    u, r = np.array(unary, np.uint8), np.array(rel, np.uint8)
    for i, k in effect.unary_flips:
        u[binding[i], k] ^= 1
    for k, i, j in effect.rel_flips:
        r[k, binding[i], binding[j]] ^= 1
    return u, r


def replay(ops: OperatorSet, problem: SymbolicProblem, steps: list[PlanStep],
           choice: np.ndarray | None = None) -> tuple[bool, str]:
    """Apply plan steps to Sigma_init with array operations (independent of the packed search).

    choice[i] selects the effect of operator i (default: most frequent). Returns (valid, reason):
    valid iff every precondition holds and the final state equals Sigma_goal.
    """
    check_problem(ops, problem)
    u = np.array(problem.init_unary, np.uint8)
    r = np.array(problem.init_rel, np.uint8)
    n = u.shape[0]
    names = ops.by_name()
    for t, (name, args) in enumerate(steps):
        base = name.split("__e")[0]
        if base not in names:
            raise ValueError(f"step {t}: unknown operator {name!r}")
        oi = names[base]
        op = ops.operators[oi]
        b = [object_index(x, n) for x in args]
        if len(b) != op.arity or len(set(b)) != len(b):
            return False, f"step {t}: {name} needs {op.arity} distinct objects, got {args}"
        if not op.holds(u[b], r[:, b][:, :, b]):
            return False, f"step {t}: precondition of {name}{tuple(args)} does not hold"
        u, r = apply_effect(u, r, op.effects[0 if choice is None else int(choice[oi])], b)
    if not (np.array_equal(u, problem.goal_unary) and np.array_equal(r, problem.goal_rel)):
        return False, "final state differs from the goal"
    return True, "ok"
