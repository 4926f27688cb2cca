"""Stub models for the planner tests: exact toy dynamics and hand-written symbols (no torch, no Drake).

The Dynamics Model is `learned.synthetic.apply_action` without noise (a physics-free pick-place that
mimics the skill); the symbols are one unary bit "on the table" and one relation "i directly on j".
"""
from __future__ import annotations

import numpy as np

from learned.synthetic import HALF_XY, apply_action


class StubModel:
    """predict_effect / symbols with the EffectModel signatures; counts predict_effect calls."""

    d_z, K = 1, 1

    def __init__(self):
        self.calls = 0
        self.rows = 0

    def predict_effect(self, X, actions):
        self.calls += 1
        actions = np.asarray(actions, dtype=np.int64).reshape(-1, 4)
        self.rows += len(actions)
        X = np.asarray(X, dtype=float)
        return np.stack([apply_action(X, a)[0][:, :3] - X[:, :3] for a in actions]) if len(actions) \
            else np.zeros((0, len(X), 3))

    def symbols(self, X):
        X = np.asarray(X, dtype=float)
        n = len(X)
        unary = (X[:, 2] < 0.04).astype(np.uint8)[:, None]
        half = HALF_XY[np.argmax(X[:, 3:5], axis=1)]
        rel = np.zeros((1, n, n), np.uint8)
        for i in range(n):
            for j in range(n):
                rel[0, i, j] = i != j and abs(X[i, 2] - X[j, 2] - 0.05) < 0.01 and \
                    bool(np.all(np.abs(X[i, :2] - X[j, :2]) <= half[j]))
        return unary, rel


def world_step(X, action):
    """The 'real' world of the tests: the same toy rules."""
    return apply_action(X, tuple(action))[0]


def two_block_domain(p_bad: float = 0.9, p_good: float = 0.3, shift: bool = False):
    """A hand-made 2-object domain: putting object p on object t (both on the table) with release
    offset +1 ('bad') or 0 ('good') gives 'p on t' with probability p_bad / p_good, else nothing.
    With `shift`, also 'pick p at -1, place on itself at +1' (a shift along y): symbolically nothing."""
    from symbolic.dataset import make_dataset
    from symbolic.operators import learn_operators

    stub = StubModel()
    X = np.array([[0.6, 0.0, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0]])
    on = np.array([[0.7, 0.1, 0.075, 1, 0], [0.7, 0.1, 0.025, 1, 0]])
    u0, r0 = stub.symbols(X)
    u1, r1 = stub.symbols(on)
    rows = []
    for action, p in (((0, 0, 1, 1), p_bad), ((0, 0, 1, 0), p_good)) + ((((0, -1, 0, 1), 0.0),) if shift else ()):
        hits = int(round(10 * p))
        rows += [(action, u1, r1)] * hits + [(action, u0, r0)] * (10 - hits)
    T = len(rows)
    data = make_dataset(np.repeat(u0[None], T, 0), np.repeat(r0[None], T, 0), np.array([a for a, _, _ in rows]),
                        np.stack([u for _, u, _ in rows]), np.stack([r for _, _, r in rows]), np.full(T, 2))
    return learn_operators(data)
