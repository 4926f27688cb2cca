"""A noisy symbolic blocks world that produces bit datasets and problems without any learned model.

Used by the tests and `bench/symbolic.py` as a stand-in for the Symbolic Model's bits. Blocks form
towers; bits: u0 = clear, u1 = on the table, u2 = large block; r0(i, j) = i directly on j,
r1(i, j) = i above j in the same tower. Pick-place (p, g, q, r):
- p != q, both clear: p lands on q with probability 0.9 - 0.1 * (|g| + |r|) (0.45 less if a large
  block goes on a small one); otherwise it falls to the table (2/3) or nothing changes (1/3).
- p == q, p clear and stacked: p is put on the table (probability 0.95, else nothing changes).
- anything else: nothing changes.
"""

from __future__ import annotations

import numpy as np

from symbolic.dataset import make_dataset
from symbolic.structs import Action, SymbolicDataset, SymbolicProblem

N_UNARY, N_RELATIONS = 3, 2


def encode(below: np.ndarray, large: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """below[i] = block under i or -1 (table) -> unary (n, 3), relations (2, n, n)."""
    n = len(below)
    u = np.zeros((n, N_UNARY), np.uint8)
    r = np.zeros((N_RELATIONS, n, n), np.uint8)
    for i in range(n):
        u[i, 0] = i not in below
        u[i, 1] = below[i] < 0
        u[i, 2] = large[i]
        if below[i] >= 0:
            r[0, i, below[i]] = 1
        j = below[i]
        while j >= 0:
            r[1, i, j] = 1
            j = below[j]
    return u, r


def random_state(n: int, rng: np.random.Generator, p_large: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Random towers: blocks in random order, each placed on the table or on a random tower top;
    each block is large with probability p_large."""
    below = np.full(n, -1)
    tops: list[int] = []
    for i in rng.permutation(n):
        if tops and rng.random() < 0.5:
            k = int(rng.integers(len(tops)))
            below[i] = tops[k]
            tops[k] = int(i)
        else:
            tops.append(int(i))
    return below, rng.random(n) < p_large


def step(below: np.ndarray, large: np.ndarray, action: Action, rng: np.random.Generator) -> np.ndarray:
    p, g, q, r = action
    below = below.copy()
    clear = [i not in below for i in range(len(below))]
    if p == q:
        if clear[p] and below[p] >= 0 and rng.random() < 0.95:
            below[p] = -1
        return below
    if not (clear[p] and clear[q]):
        return below
    success = 0.9 - 0.1 * (abs(g) + abs(r)) - (0.45 if large[p] and not large[q] else 0.0)
    u = rng.random()
    if u < success:
        below[p] = q
    elif u < success + (1 - success) * 2 / 3:
        below[p] = -1
    return below


def random_action(n: int, rng: np.random.Generator) -> Action:
    p, q = (int(x) for x in rng.integers(n, size=2))
    g, r = (int(x) for x in rng.integers(-1, 2, size=2))
    return (p, g, q, r)


def random_dataset(n_transitions: int, n_objects=(2, 3, 4), seed: int = 0, p_large: float = 0.5) -> SymbolicDataset:
    """Random scenes (n drawn from n_objects), one random pick-place each."""
    rng = np.random.default_rng(seed)
    sizes = np.atleast_1d(n_objects)
    n_max = int(sizes.max())
    T = n_transitions
    up = np.zeros((T, n_max, N_UNARY), np.uint8)
    rp = np.zeros((T, N_RELATIONS, n_max, n_max), np.uint8)
    uq, rq = up.copy(), rp.copy()
    acts = np.zeros((T, 4), np.int64)
    ns = np.zeros(T, np.int64)
    for t in range(T):
        n = int(rng.choice(sizes))
        below, large = random_state(n, rng, p_large)
        a = random_action(n, rng)
        after = step(below, large, a, rng)
        ns[t], acts[t] = n, a
        up[t, :n], rp[t, :, :n, :n] = encode(below, large)
        uq[t, :n], rq[t, :, :n, :n] = encode(after, large)
    return make_dataset(up, rp, acts, uq, rq, ns)


def random_problem(n: int, k: int, seed: int = 0, p_large: float = 0.5) -> tuple[SymbolicProblem, list[Action]]:
    """Random initial scene, goal after k random *effective* actions (each changes the state)."""
    rng = np.random.default_rng(seed)
    below, large = random_state(n, rng, p_large)
    init = encode(below, large)
    actions: list[Action] = []
    while len(actions) < k:
        a = random_action(n, rng)
        after = step(below, large, a, rng)
        if not np.array_equal(after, below):
            actions.append(a)
            below = after
    goal = encode(below, large)
    return SymbolicProblem(init[0], init[1], goal[0], goal[1]), actions
