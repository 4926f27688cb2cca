"""How far executed steps land from the Dynamics Model's prediction, and whether its bound said so.

For every executed action the rows record, from the state the world was in before it, the model's
prediction (the members' mean), its 95 % bound (`learned.ensemble.EffectDistribution.bound`: the
distance the farthest-off block stays within 19 times in 20 under the members' mixture), the
members' disagreement and the scatter they predict, and the observed miss (the largest distance of a
block from its predicted place). A calibrated model's miss exceeds its bound in about 5 % of steps,
whatever the action class and the number of blocks; the report counts it (`evaluation.report`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from learned.ensemble import EffectDistribution, distribution_of

SMALL, LARGE = 0, 1  # column of the one-hot type in X[:, 3:5]


def action_class(X: np.ndarray, action: Sequence[int]) -> str:
    """A pick-place in words: what is moved ("cube", "bar"), where ("on", "beside" a cube, "on the middle"
    or "end" of a bar, or "shifted" along itself when it is placed on itself)."""
    pick, _, place, release = (int(v) for v in action)
    kind = "bar" if X[pick, 3 + LARGE] > 0.5 else "cube"
    if pick == place:
        return f"{kind} shifted"
    if X[place, 3 + LARGE] > 0.5:
        return f"{kind} on a bar's {'middle' if release == 0 else 'end'}"
    return f"{kind} {'on' if release == 0 else 'beside'} a cube"


@dataclass(frozen=True)
class StepPrediction:
    """The Dynamics Model's prediction of one executed step against what the world did (metres)."""
    action_class: str
    miss_m: float        # the largest distance of a block from its predicted place
    bound_m: float       # the 95 % bound of that distance
    epistemic_m: float   # the members' disagreement (largest over blocks)
    aleatoric_m: float   # the scatter the members predict (largest over blocks)

    @property
    def exceeded(self) -> bool:
        return self.miss_m > self.bound_m

    def record(self) -> dict:
        return {"class": self.action_class, "miss_m": round(self.miss_m, 6), "bound_m": round(self.bound_m, 6),
                "epistemic_m": round(self.epistemic_m, 6), "aleatoric_m": round(self.aleatoric_m, 6)}


def step_predictions(model, states: Sequence[np.ndarray], actions: Sequence) -> list[StepPrediction]:
    """Per executed action k: the prediction from states[k] against states[k + 1] (states: X_0 .. X_m)."""
    m = len(states) - 1
    if m <= 0:
        return []
    Xs = np.stack([np.asarray(X, dtype=float) for X in states[:m]])
    a = np.asarray([tuple(int(v) for v in act) for act in actions[:m]], dtype=np.int64)
    dist: EffectDistribution = distribution_of(model, Xs, a)
    predicted = Xs[:, :, :3] + dist.mean
    observed = np.stack([np.asarray(X, dtype=float)[:, :3] for X in states[1:m + 1]])
    miss = np.linalg.norm(observed - predicted, axis=-1).max(axis=-1)
    bound, epistemic, aleatoric = dist.bound(), dist.epistemic_m, dist.aleatoric_m
    return [StepPrediction(action_class(Xs[k], a[k]), float(miss[k]), float(bound[k]), float(epistemic[k]),
                           float(aleatoric[k])) for k in range(m)]
