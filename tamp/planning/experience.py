"""What a closed loop learns from its own steps: the Dynamics Model corrected where the world showed it wrong.

A pick-and-place ends where the place target and the blocks around it put the picked block, wherever it
was picked from. So when an executed step lands far from the Dynamics Model's prediction (`Miss`), the
same action in a scene whose other blocks are where they were will most likely land the same way: a bar
released beside a cube that came to rest on the neighbouring cube does so again, and a loop that asks the
unchanged model plans that step again and again. `Experienced` is the Dynamics Model with each such miss
added to its prediction of that action in such scenes, for the rest of the loop (`LoopConfig.learn_misses`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from tamp.planning.verify import DynamicsModel, predict_many


@dataclass(frozen=True)
class Miss:
    """One executed step that landed far from its prediction."""

    X: np.ndarray  # (n, 5) the observed state the action was taken from
    action: tuple[int, ...]
    residual: np.ndarray  # (n, 3) metres: the observed displacement minus the model's prediction of it

    @classmethod
    def of(cls, model: DynamicsModel, X: np.ndarray, action, X_next: np.ndarray) -> Miss:
        """The step X --action--> X_next (observed) against `model`'s prediction."""
        X, X_next = np.asarray(X, dtype=float), np.asarray(X_next, dtype=float)
        action = tuple(int(v) for v in action)
        predicted = model.predict_effect(X, np.asarray([action], dtype=np.int64))[0]
        return cls(X, action, (X_next[:, :3] - X[:, :3]) - predicted)

    @property
    def distance(self) -> float:
        """Metres: how far the worst block landed from its prediction."""
        return float(np.linalg.norm(self.residual, axis=1).max(initial=0.0))

    def applies(self, Xs: np.ndarray, actions: np.ndarray, within: float) -> np.ndarray:
        """Which rows b (bool (B,)) take this step's action in a scene Xs[b] (B, n, 5) whose blocks other than
        the picked one are each within `within` metres (3-D) of where they were."""
        same = np.all(actions == np.asarray(self.action), axis=1)
        if not same.any():
            return same
        others = np.arange(len(self.X)) != self.action[0]
        apart = np.linalg.norm(Xs[:, others, :3] - self.X[None, others, :3], axis=2).max(axis=1, initial=0.0)
        return same & (apart <= within)


class Experienced:
    """`model` with the residual of the latest applicable `Miss` added to its predictions (`Miss.applies`).
    Anything else (the networks' config, the ensemble's spread) is the model's own."""

    def __init__(self, model: DynamicsModel, misses: Sequence[Miss], within: float) -> None:
        self.model, self.misses, self.within = model, tuple(misses), within

    def predict_effect(self, X: np.ndarray, actions) -> np.ndarray:
        actions = np.asarray(actions, dtype=np.int64).reshape(-1, 4)
        e = self.model.predict_effect(X, actions)
        return self._corrected(np.broadcast_to(np.asarray(X, dtype=float), (len(actions), *np.shape(X))), actions, e)

    def predict_effects(self, Xs: np.ndarray, actions) -> np.ndarray:
        actions = np.asarray(actions, dtype=np.int64).reshape(-1, 4)
        return self._corrected(np.asarray(Xs, dtype=float), actions, predict_many(self.model, Xs, actions))

    def _corrected(self, Xs: np.ndarray, actions: np.ndarray, e: np.ndarray) -> np.ndarray:
        e = np.array(e, dtype=float)
        done = np.zeros(len(actions), dtype=bool)
        for miss in reversed(self.misses):  # the latest miss of an action in a scene decides
            rows = miss.applies(Xs, actions, self.within) & ~done
            e[rows] += miss.residual
            done |= rows
        return e

    def __getattr__(self, name: str):
        if name == "model":  # not yet set (a copy being built): no recursion through the line below
            raise AttributeError(name)
        return getattr(self.model, name)


def experienced(model: DynamicsModel, misses: Sequence[Miss], within: float) -> DynamicsModel:
    """`model` corrected by `misses` (itself when there are none)."""
    return Experienced(model, misses, within) if misses else model
