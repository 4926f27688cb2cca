"""How far executed steps land from the Dynamics Model's prediction, and whether its bound said so.

For every executed action the rows record, from the state the world was in before it, the model's
prediction (the members' mean), its 95 % bound (`learned.ensemble.EffectDistribution.bound`: the
distance the farthest-off block stays within 19 times in 20 under the members' mixture), the
members' disagreement and the scatter they predict, and the observed miss (the largest distance of a
block from its predicted place). A calibrated model's miss exceeds its bound in about 5 % of steps,
whatever the action class and the number of blocks; the report counts it (`evaluation.report`), by action class
and by the scene a step starts from (`start_scene`: the model misses where blocks are stacked or lean).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numpy as np

from tamp.planning.vocabulary import BLOCK_HEIGHT, LARGE

if TYPE_CHECKING:  # the report reads `SCENES` without loading torch
    from learned.ensemble import EffectDistribution

# metres: a block whose centre lies farther than this from every height an upright block rests at leans or is tilted
LEVEL_TOLERANCE_M = 0.01
SCENES = ("blocks on the table", "a stack", "a leaning block")  # `start_scene`'s words, simplest first


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


def start_scene(X: np.ndarray) -> str:
    """The scene a step starts from, in words (`SCENES`): every block upright on the table, a stack (every block at
    a height an upright block rests at, some above the table), or a leaning block (a centre between those heights:
    leaning on another block, or tilted, which X does not describe)."""
    z = np.asarray(X)[:, 2] - BLOCK_HEIGHT / 2
    if (np.abs(z - BLOCK_HEIGHT * np.round(z / BLOCK_HEIGHT)) > LEVEL_TOLERANCE_M).any():
        return SCENES[2]
    return SCENES[1] if (z > LEVEL_TOLERANCE_M).any() else SCENES[0]


@dataclass(frozen=True)
class StepPrediction:
    """The Dynamics Model's prediction of one executed step against what the world did (metres)."""
    action_class: str
    miss_m: float        # the largest distance of a block from its predicted place
    bound_m: float       # the 95 % bound of that distance
    epistemic_m: float   # the members' disagreement (largest over blocks)
    aleatoric_m: float   # the scatter the members predict (largest over blocks)
    scene: str = SCENES[0]  # the scene the step starts from (`start_scene`)

    @property
    def exceeded(self) -> bool:
        return self.miss_m > self.bound_m

    def record(self) -> dict:
        return {"class": self.action_class, "miss_m": round(self.miss_m, 6), "bound_m": round(self.bound_m, 6),
                "epistemic_m": round(self.epistemic_m, 6), "aleatoric_m": round(self.aleatoric_m, 6),
                "scene": self.scene}


def step_predictions(model, states: Sequence[np.ndarray], actions: Sequence) -> list[StepPrediction]:
    """Per executed action k: the prediction from states[k] against states[k + 1] (states: X_0 .. X_m)."""
    m = len(states) - 1
    if m <= 0:
        return []
    from learned.ensemble import distribution_of

    Xs = np.stack([np.asarray(X, dtype=float) for X in states[:m]])
    a = np.asarray([tuple(int(v) for v in act) for act in actions[:m]], dtype=np.int64)
    dist: EffectDistribution = distribution_of(model, Xs, a)
    predicted = Xs[:, :, :3] + dist.mean
    observed = np.stack([np.asarray(X, dtype=float)[:, :3] for X in states[1:m + 1]])
    miss = np.linalg.norm(observed - predicted, axis=-1).max(axis=-1)
    bound, epistemic, aleatoric = dist.bound(), dist.epistemic_m, dist.aleatoric_m
    return [StepPrediction(action_class(Xs[k], a[k]), float(miss[k]), float(bound[k]), float(epistemic[k]),
                           float(aleatoric[k]), start_scene(Xs[k])) for k in range(m)]
