"""The paper's Level-1 symbolic planning written the plain way: the oracle and the baseline.

Every ground action of the task is enumerated up front (operator, then binding in
`itertools.permutations` order), each with a (mask, value) precondition over the packed state and one
XOR mask per effect; each sampled domain gets a breadth-first search of its own with the goal test at
generation (`plan_each_domain`: N domains drawn with a random stream per domain, searches reused
between domains that agree on the operators a search touched, a shared expansion budget),
independent of `symbolic.lifted` and `symbolic.search`: `tests/symbolic/test_search.py` checks
that one shared search gives every domain this plan, and `bench/symbolic.py` measures the shared
search against it.
"""

from __future__ import annotations

import itertools
import time
from collections import deque

import numpy as np

from symbolic.atoms import n_bits
from symbolic.sampling import EffectSampler
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
            known = op.known_bits()
            local_u = [(i, k) for i in range(a) for k in range(d)]
            local_r = [(k, i, j) for k in range(K) for i in range(a) for j in range(a)]
            for b in itertools.permutations(range(n), a):
                pos = np.array([b[i] * d + k for i, k in local_u]
                               + [n * d + k * n * n + b[i] * n + b[j] for k, i, j in local_r], dtype=np.int64)
                self.op_index.append(oi)
                self.binding.append(b)
                self.pre_mask.append(_int(pos[known]))
                self.pre_val.append(_int(pos[known & pre]))
                self.flips.append(tuple(_int([b[i] * d + k for i, k in e.unary_flips]
                                             + [n * d + k * n * n + b[i] * n + b[j] for k, i, j in e.rel_flips])
                                        for e in op.effects))

        wide = self.n_bits > 62  # int64 when the state fits (as the planner did), else Python ints
        self._pm = np.array(self.pre_mask, dtype=object if wide else np.int64)
        self._pv = np.array(self.pre_val, dtype=object if wide else np.int64)
        self._wide = wide
        self._cache: dict[int, list[int]] = {}

    def applicable(self, state: int) -> list[int]:
        """Ground actions whose precondition holds in `state`, in order (cached per state)."""
        hit = self._cache.get(state)
        if hit is None:
            s = state if self._wide else np.int64(state)
            hit = self._cache[state] = np.flatnonzero((s & self._pm) == self._pv).tolist()
        return hit


def bfs(task: GroundTask, choice, init: int, goal: int, nonempty: bool = False, max_expansions: int = 100_000):
    """(status, plan as [(operator, binding)], states along it, states expanded) of a breadth-first
    search in one domain."""
    if init == goal and not nonempty:
        return PlannerStatus.SOLVED, [], [init], []
    parent: dict[int, tuple[int, int] | None] = {init: None}
    frontier, expanded = deque([init]), []
    while frontier:
        s = frontier.popleft()
        expanded.append(s)
        if len(expanded) > max_expansions:
            return PlannerStatus.TIMEOUT, None, None, expanded
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
                        states[::-1], expanded)
            if t not in parent:
                parent[t] = (s, g)
                frontier.append(t)
    return PlannerStatus.UNSOLVABLE, None, None, expanded


def sample_per_domain_stream(ops: OperatorSet, n_domains: int, seed: int) -> np.ndarray:
    """(N, n_operators) effect choices drawn per domain: domain k's uniforms from its own
    `np.random.default_rng([seed, k])`, one per operator, compared with the cumulative probabilities."""
    cum = EffectSampler(ops).cumulative
    return np.stack([(np.random.default_rng([seed, k]).random(len(ops))[:, None] >= cum).sum(axis=1)
                     for k in range(n_domains)])


def plan_each_domain(ops: OperatorSet, task: GroundTask, init: int, goal: int, n_domains: int, seed: int,
                     nonempty: bool = False, budget: int = 10_000) -> dict:
    """Level 1's symbolic planning as it was: sample N domains, one BFS per domain (a search is reused
    for a later domain whose choices agree on every operator it touched), `budget` expansions shared
    by all searches. Returns per-domain plans and the seconds of sampling and search."""
    t0 = time.perf_counter()
    choices = sample_per_domain_stream(ops, n_domains, seed)
    sampling = time.perf_counter() - t0
    t0 = time.perf_counter()
    task._cache.clear()
    memo: list[tuple[np.ndarray, np.ndarray, tuple]] = []
    plans: list[tuple | None] = []
    left = budget
    for k in range(n_domains):
        c = choices[k]
        hit = next((res for ops_, vals, res in memo if np.array_equal(c[ops_], vals)), None)
        if hit is None:
            if left <= 0:
                plans.append(None)
                continue
            status, plan, _, expanded = bfs(task, c, init, goal, nonempty, left)
            left -= len(expanded)
            touched = np.array(sorted({task.op_index[g] for s in expanded for g in task.applicable(s)}), np.int64)
            hit = (status, plan)
            if status is not PlannerStatus.TIMEOUT:
                memo.append((touched, c[touched], hit))
        plans.append(hit)
    task._cache.clear()
    return {"plans": plans, "sampling": sampling, "search": time.perf_counter() - t0}

