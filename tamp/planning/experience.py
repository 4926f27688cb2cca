"""What the world did in this loop: the Dynamics Model corrected where the loop meets a miss again.

The loop that does not know k executes one action a round and observes the result. When an action lands
`closed_loop.REMEMBER_M` metres (2 cm) or more from the prediction, the loop records the observed transition. Once the
world has done the same action alike `closed_loop.REMEMBER_ALIKE` times (2), the loop trusts the miss: whenever a
planning call asks the model about that action from a state in which the blocks that decide its outcome lie
within that distance of where they were (every block but the picked one, when it is carried to another block;
all of them for a shift along itself), the prediction is what the world did: every block displaced as it was, a
carried block brought to where it landed. When the world does otherwise there, the miss was scatter (the
picked block's yaw, which the state does not hold, can decide a placement) and is trusted no longer.

A cube placed on the low end of a tilted bar slides off to the same spot every time; without this the planner,
seeing the same optimistic prediction from wherever the cube lay, tried it again and again until its actions ran
out (`revisits` does not see such repeats: the cube starts elsewhere each time).

This is data aggregation at the scale of one episode (`tamp practice` aggregates executed transitions between
rounds of training): a nearest-neighbour model of the world's misses in front of the learned one, with no
training and no cost while nothing was missed.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tamp.planning.verify import DynamicsModel, predict_many
from tamp.planning.vocabulary import action_words


@dataclass(frozen=True)
class Miss:
    """One executed action the model missed: the observed states before and after it."""
    X: np.ndarray       # (n, 5) observed state before the action
    action: tuple       # (pick, grasp, place, release)
    X_next: np.ndarray  # (n, 5) observed state after it
    missed_m: float     # metres: how far the block missed most landed from the prediction

    def describe(self) -> str:
        return (f"remembered: {action_words(self.action)} landed {self.missed_m * 100:.1f} cm from its prediction, "
                f"as it did before; from states like that one it is predicted as the world did it")

    @property
    def carried(self) -> bool:
        """Whether the picked block is carried to a place relative to another block (its start decides nothing);
        else it is placed relative to itself (a shift)."""
        return self.action[0] != self.action[2]

    def matches(self, Xs: np.ndarray, actions: np.ndarray, within: float) -> np.ndarray:
        """(B,) which of B (state, action) queries this miss speaks for: the same action, and every block that
        decides its outcome within `within` metres of where it was (all but a carried picked block)."""
        same = np.all(actions == np.asarray(self.action), axis=1)
        blocks = np.ones(len(self.X), dtype=bool)
        if self.carried:
            blocks[self.action[0]] = False
        if not same.any() or not blocks.any():
            return same
        distance = np.linalg.norm(Xs[:, blocks, :3] - self.X[None, blocks, :3], axis=-1).max(axis=-1)
        return same & (distance < within)

    def effects(self, Xs: np.ndarray) -> np.ndarray:
        """(B, n, 3) metres: what the world did, from B states this miss speaks for: every block displaced as it
        was, a carried picked block brought to where it landed."""
        out = np.repeat((self.X_next[:, :3] - self.X[:, :3])[None], len(Xs), axis=0)
        if self.carried:
            pick = self.action[0]
            out[:, pick] = self.X_next[pick, :3] - Xs[:, pick, :3]
        return out

    def repeated_by(self, X: np.ndarray, X_next: np.ndarray, within: float) -> bool:
        """Whether the world did it again from X (a state this miss speaks for): every block of X_next within
        `within` metres of where this miss puts it."""
        landed = X[:, :3] + self.effects(X[None])[0]
        return bool(np.linalg.norm(X_next[:, :3] - landed, axis=1).max(initial=0.0) < within)


@dataclass
class Experience:
    """The misses of one loop, in the order they happened, and those it trusts: a miss the world repeated alike
    (`alike` times in all, from states it speaks for) is trusted until the world does otherwise there, which makes
    it scatter, not a rule (a later trusted miss speaks for a state over an earlier one)."""
    within: float  # metres: the miss threshold, and how close the deciding blocks must be for a miss to apply
    alike: int = 2  # misses alike before the loop trusts them (1: the first)
    misses: list[Miss] = field(default_factory=list)
    trusted: list[Miss] = field(default_factory=list)

    def expect(self, model: DynamicsModel, X: np.ndarray, action) -> np.ndarray:
        """(n, 3) metres: where the plain `model` with the trusted misses puts the blocks after `action` from X."""
        X = np.asarray(X, dtype=float)
        a = np.asarray([tuple(int(v) for v in action)], dtype=np.int64)
        return X[:, :3] + self.corrected(X[None], a, model.predict_effect(X, a))[0]

    def remember(self, model: DynamicsModel, X: np.ndarray, action, X_next: np.ndarray,
                 expected: np.ndarray | None = None) -> Miss | None:
        """Record the executed (X, action, X_next) if it landed `within` or more from `expected` (default: `expect`
        of the plain `model`), and trust it if the world did it `alike` times; the Miss, or None."""
        X, X_next = np.asarray(X, dtype=float), np.asarray(X_next, dtype=float)
        a = np.asarray([tuple(int(v) for v in action)], dtype=np.int64)
        predicted = self.expect(model, X, action) if expected is None else expected
        missed = float(np.linalg.norm(X_next[:, :3] - predicted, axis=1).max(initial=0.0))
        if missed < self.within:
            return None
        miss = Miss(X.copy(), tuple(int(v) for v in a[0]), X_next.copy(), missed)
        self.trusted = [m for m in self.trusted if not m.matches(X[None], a, self.within)[0]]  # the world did otherwise
        repeated = sum(m.matches(X[None], a, self.within)[0] and m.repeated_by(X, X_next, self.within)
                       for m in self.misses)
        self.misses.append(miss)
        if repeated + 1 >= self.alike:
            self.trusted.append(miss)
        return miss

    def trusts(self, miss: Miss | None) -> bool:
        return miss is not None and any(m is miss for m in self.trusted)

    def corrected(self, Xs: np.ndarray, actions: np.ndarray, effects: np.ndarray) -> np.ndarray:
        """(B, n, 3) the plain model's displacements `effects` of B (state, action) queries, with what the world did
        where the latest trusted miss that speaks for a query says so."""
        out = np.array(effects, dtype=float, copy=True)
        for miss in self.trusted:
            rows = np.flatnonzero(miss.matches(Xs, actions, self.within))
            if len(rows):
                out[rows] = miss.effects(Xs[rows])
        return out

    def over(self, model: DynamicsModel) -> DynamicsModel:
        """`model` with this experience (the model itself while no miss is trusted)."""
        return model if not self.trusted else Experienced(model, self)


class Experienced:
    """A Dynamics Model whose predictions are corrected by a loop's `Experience` (the planner's API: the
    single-scene and batched predictions, and the distribution, its members' means replaced alike)."""

    def __init__(self, model: DynamicsModel, experience: Experience) -> None:
        self.model, self.experience = model, experience

    def __getattr__(self, name: str) -> Any:  # config, info, ... of the wrapped model
        if name in ("model", "experience"):  # not set yet (unpickling)
            raise AttributeError(name)
        return getattr(self.model, name)

    def predict_effect(self, X: np.ndarray, actions) -> np.ndarray:
        a = np.asarray(actions, dtype=np.int64).reshape(-1, 4)
        X = np.asarray(X, dtype=float)
        return self.experience.corrected(np.broadcast_to(X, (len(a), *X.shape)), a, self.model.predict_effect(X, a))

    def predict_effects(self, Xs: np.ndarray, actions) -> np.ndarray:
        Xs, a = np.asarray(Xs, dtype=float), np.asarray(actions, dtype=np.int64).reshape(-1, 4)
        return self.experience.corrected(Xs, a, predict_many(self.model, Xs, a))

    def distribution(self, Xs: np.ndarray, actions):
        from learned.ensemble import EffectDistribution, distribution_of

        Xs, a = np.asarray(Xs, dtype=float), np.asarray(actions, dtype=np.int64).reshape(-1, 4)
        plain = distribution_of(self.model, Xs, a)
        means = np.stack([self.experience.corrected(Xs, a, member) for member in plain.means])
        return EffectDistribution(means, plain.variances)


def remembers(model: DynamicsModel | None, states: np.ndarray, actions) -> bool:
    """Whether `model` carries a loop's experience that speaks for any of the (states[t], actions[t]): a plan's
    own earlier prediction of those steps no longer decides (`keep_rest`)."""
    if not isinstance(model, Experienced) or not len(actions):
        return False
    a = np.asarray([tuple(int(v) for v in act) for act in actions], dtype=np.int64)
    Xs = np.asarray(states, dtype=float)[:len(a)]
    return any(miss.matches(Xs, a, model.experience.within).any() for miss in model.experience.trusted)


__all__ = ["Experience", "Experienced", "Miss", "remembers"]
