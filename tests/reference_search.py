"""The paper's Level-1 search written the plain way, as an oracle for `symbolic.search`.

Every ground action of the task is enumerated up front (operator, then binding in
`itertools.permutations` order), each with a (mask, value) precondition over the packed state and one
XOR mask per effect, and each sampled domain gets a breadth-first search of its own with the goal
test at generation. This was the planner's implementation until the shared search replaced it; it
stays here, independent of `symbolic.lifted`, to check that one search serves N domains exactly.
"""

from __future__ import annotations

import itertools
from collections import deque

import numpy as np

from symbolic.atoms import n_bits
from symbolic.structs import OperatorSet, PlannerStatus


def _int(positions) -> int:
    value = 0
    for p in positions:
        value |= 1 << int(p)
    return value


class GroundTask:
    """All ground actions of an operator set in an n-object scene (operators of arity <= n)."""

    def __init__(self, ops: OperatorSet, n: int):
        d, K = ops.n_unary, ops.n_relations
        self.n_bits = n_bits(n, d, K)
        self.op_index, self.binding, self.pre_mask, self.pre_val, self.flips = [], [], [], [], []
        for oi, op in enumerate(ops.operators):
            a = op.arity
            if a > n:
                continue
            pre = np.concatenate([op.pre_unary.ravel(), op.pre_rel.ravel()]).astype(bool)
            local_u = [(i, k) for i in range(a) for k in range(d)]
            local_r = [(k, i, j) for k in range(K) for i in range(a) for j in range(a)]
            for b in itertools.permutations(range(n), a):
                pos = np.array([b[i] * d + k for i, k in local_u]
                               + [n * d + k * n * n + b[i] * n + b[j] for k, i, j in local_r], dtype=np.int64)
                self.op_index.append(oi)
                self.binding.append(b)
                self.pre_mask.append(_int(pos))
                self.pre_val.append(_int(pos[pre]))
                self.flips.append(tuple(_int([b[i] * d + k for i, k in e.unary_flips]
                                             + [n * d + k * n * n + b[i] * n + b[j] for k, i, j in e.rel_flips])
                                        for e in op.effects))

    def applicable(self, state: int) -> list[int]:
        return [g for g, (m, v) in enumerate(zip(self.pre_mask, self.pre_val)) if state & m == v]


def bfs(task: GroundTask, choice, init: int, goal: int, nonempty: bool = False, max_expansions: int = 100_000):
    """(status, plan as [(operator, binding)], states) of a breadth-first search in one domain."""
    if init == goal and not nonempty:
        return PlannerStatus.SOLVED, [], [init]
    parent: dict[int, tuple[int, int] | None] = {init: None}
    frontier, expanded = deque([init]), 0
    while frontier:
        s = frontier.popleft()
        expanded += 1
        if expanded > max_expansions:
            return PlannerStatus.TIMEOUT, None, None
        for g in task.applicable(s):
            t = s ^ task.flips[g][int(choice[task.op_index[g]])]
            if t == goal:
                plan, states, step = [g], [t, s], parent[s]
                while step is not None:
                    u, g2 = step
                    plan.append(g2)
                    states.append(u)
                    step = parent[u]
                return (PlannerStatus.SOLVED, [(task.op_index[g], task.binding[g]) for g in plan[::-1]],
                        states[::-1])
            if t not in parent:
                parent[t] = (s, g)
                frontier.append(t)
    return PlannerStatus.UNSOLVABLE, None, None
