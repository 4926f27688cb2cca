"""Grounding lifted operators in an n-object scene, successor generation, and plan replay.

A ground action binds an operator's parameters to distinct scene objects. Its precondition is a
(mask, value) pair over the packed state (see `atoms.py`); since the precondition fixes every bit the
effect touches, each effect is an XOR mask. The grounded task is built once per (operator set, n)
and shared by all sampled domains of a problem: a domain only chooses which effect each operator uses.
"""

from __future__ import annotations

import itertools

import numpy as np

from symbolic.atoms import check_bits, n_bits, object_index, object_name, pack_state
from symbolic.structs import Action, OperatorSet, PlanStep, SymbolicProblem


def _int_from_positions(positions: np.ndarray) -> int:
    value = 0
    for p in positions.tolist():
        value |= 1 << p
    return value


class GroundTask:
    """All ground actions of an operator set in an n-object scene.

    scope="subset": operators of arity <= n bind to any ordered tuple of distinct objects (objects
    that are not parameters are untouched); scope="exact": only operators of arity == n.
    """

    def __init__(self, ops: OperatorSet, n: int, scope: str = "subset"):
        if scope not in ("subset", "exact"):
            raise ValueError(f"scope must be 'subset' or 'exact', got {scope!r}")
        self.ops, self.n, self.scope = ops, n, scope
        d, K = ops.n_unary, ops.n_relations
        self.n_bits = n_bits(n, d, K)
        self.op_index: list[int] = []
        self.binding: list[tuple[int, ...]] = []
        self.pre_mask: list[int] = []
        self.pre_val: list[int] = []
        self.flips: list[tuple[int, ...]] = []  # one XOR mask per effect of the operator
        # Bits that belong to one object alone: its unary bits and its relations with itself.
        self.own_mask = [_int_from_positions(np.concatenate([
            i * d + np.arange(d), n * d + np.arange(K) * n * n + i * n + i])) for i in range(n)]
        self.buckets: dict[tuple[int, int], list[int]] = {}
        for oi, op in enumerate(ops.operators):
            a = op.arity
            if a > n or (scope == "exact" and a != n):
                continue
            pre_flat = np.concatenate([op.pre_unary.ravel(), op.pre_rel.ravel()]).astype(bool)
            local_u = [(i, k) for i in range(a) for k in range(d)]
            local_r = [(k, i, j) for k in range(K) for i in range(a) for j in range(a)]
            for b in itertools.permutations(range(n), a):
                pos = np.array([b[i] * d + k for i, k in local_u]
                               + [n * d + k * n * n + b[i] * n + b[j] for k, i, j in local_r], dtype=np.int64)
                mask, val = _int_from_positions(pos), _int_from_positions(pos[pre_flat])
                flips = tuple(_int_from_positions(np.array(
                    [b[i] * d + k for i, k in e.unary_flips]
                    + [n * d + k * n * n + b[i] * n + b[j] for k, i, j in e.rel_flips], dtype=np.int64))
                    for e in op.effects)
                g = len(self.op_index)
                self.op_index.append(oi)
                self.binding.append(b)
                self.pre_mask.append(mask)
                self.pre_val.append(val)
                self.flips.append(flips)
                key = (b[0], val & self.own_mask[b[0]])
                self.buckets.setdefault(key, []).append(g)
        self._succ: dict[int, tuple[tuple[int, ...], tuple[int, ...]]] = {}
        # States of at most 62 bits fit in int64: test every precondition in one vectorized pass.
        self._vectorized = self.n_bits <= 62
        if self._vectorized:
            self._pm = np.array(self.pre_mask, dtype=np.int64)
            self._pv = np.array(self.pre_val, dtype=np.int64)
            self._opi = np.array(self.op_index, dtype=np.int64)

    def __len__(self) -> int:
        return len(self.op_index)

    def clear_cache(self) -> None:
        """Forget the applicable actions cached per state (kept ground actions)."""
        self._succ.clear()

    def applicable(self, state: int) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """(ground action ids in ascending order, their operator ids) applicable in `state`; cached."""
        hit = self._succ.get(state)
        if hit is not None:
            return hit
        if self._vectorized:
            gs_arr = np.flatnonzero((np.int64(state) & self._pm) == self._pv)
            hit = (tuple(gs_arr.tolist()), tuple(self._opi[gs_arr].tolist()))
            self._succ[state] = hit
            return hit
        cands: list[int] = []
        for o in range(self.n):
            cands += self.buckets.get((o, state & self.own_mask[o]), ())
        cands.sort()
        pm, pv, opi = self.pre_mask, self.pre_val, self.op_index
        gs = tuple(g for g in cands if state & pm[g] == pv[g])
        hit = (gs, tuple(opi[g] for g in gs))
        self._succ[state] = hit
        return hit

    def step(self, g: int) -> PlanStep:
        op = self.ops.operators[self.op_index[g]]
        return op.name, tuple(object_name(o) for o in self.binding[g])

    def action(self, g: int) -> Action:
        return self.ops.operators[self.op_index[g]].action(self.binding[g])


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
        if not (np.array_equal(u[b], op.pre_unary) and np.array_equal(r[:, b][:, :, b], op.pre_rel)):
            return False, f"step {t}: precondition of {name}{tuple(args)} does not hold"
        e = op.effects[0 if choice is None else int(choice[oi])]
        for i, k in e.unary_flips:
            u[b[i], k] ^= 1
        for k, i, j in e.rel_flips:
            r[k, b[i], b[j]] ^= 1
    if not (np.array_equal(u, problem.goal_unary) and np.array_equal(r, problem.goal_rel)):
        return False, "final state differs from the goal"
    return True, "ok"
