"""A Dynamics Model that knows its doubt: an ensemble of effect models with spread heads.

Two kinds of doubt, as in probabilistic ensembles (Chua et al., PETS, NeurIPS 2018):

- where the model has seen too little: M members trained on bootstrap resamples of the data disagree
  (epistemic);
- where the world itself scatters: each member predicts a Gaussian per object and axis about its mean
  (its ``spread`` head, `learned.spread`; aleatoric).

The planner's prediction is the members' mean. The *bound* of a prediction is the 95 % quantile of
the worst block's distance from that mean under the members' mixture of Gaussians: the distance the
step's farthest-off block stays within 19 times out of 20, if the model is calibrated
(`EffectDistribution.bound`, computed from a fixed number of seeded samples, so it is deterministic).

File: one checkpoint (format ``learned-effect-ensemble/1``): ``{"format", "members": [{"config",
"state_dict"}, ...], "info": {...}}``, loaded with ``weights_only=True`` like a single model's.
`load_dynamics` reads either kind.
"""
from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch

from .checkpoint import CKPT_FORMAT, model_from_payload, read_checkpoint
from .dataset import atomic_write_bytes
from .effects import as_action_array
from .model import EffectModel, ModelConfig

ENSEMBLE_FORMAT = "learned-effect-ensemble/1"
BOUND_QUANTILE = 0.95  # the bound a step's miss is measured against (calibration: exceeded 1 step in 20)
BOUND_SAMPLES = 256  # samples of the mixture per prediction; seeded, so a bound never varies between calls


@dataclass(frozen=True)
class EffectDistribution:
    """Predicted displacements of B actions: each member's mean and variance per object and axis."""
    means: np.ndarray      # (M, B, n, 3) metres
    variances: np.ndarray  # (M, B, n, 3) metres squared (zeros: a member without a spread head)

    def __post_init__(self) -> None:
        if self.means.shape != self.variances.shape or self.means.ndim != 4 or self.means.shape[-1] != 3:
            raise ValueError(f"means and variances must both be (M, B, n, 3), got {self.means.shape} and "
                             f"{self.variances.shape}")

    @property
    def mean(self) -> np.ndarray:
        """(B, n, 3) the members' mean displacement, metres: the planner's prediction."""
        return self.means.mean(axis=0)

    @property
    def epistemic_m(self) -> np.ndarray:
        """(B,) the largest over blocks of the members' disagreement (std of their means, norm over axes), metres."""
        return np.sqrt(self.means.var(axis=0).sum(-1)).max(axis=-1, initial=0.0)

    @property
    def aleatoric_m(self) -> np.ndarray:
        """(B,) the largest over blocks of the scatter the members predict (root of the mean variance, norm), metres."""
        return np.sqrt(self.variances.mean(axis=0).sum(-1)).max(axis=-1, initial=0.0)

    def bound(self, quantile: float = BOUND_QUANTILE, samples: int = BOUND_SAMPLES, seed: int = 0) -> np.ndarray:
        """(B,) metres: the `quantile` of max_i ||Y_i - mean_i|| for Y drawn from the members' mixture (a member
        uniformly, then its Gaussian), from `samples` draws of a generator seeded with `seed`."""
        M, B, n, _ = self.means.shape
        if B == 0 or n == 0:
            return np.zeros(B)
        rng = np.random.default_rng(seed)
        member = rng.integers(0, M, size=(samples, B))
        noise = rng.standard_normal((samples, B, n, 3))
        batch = np.arange(B)[None, :]
        draws = self.means[member, batch] + noise * np.sqrt(self.variances[member, batch])
        worst = np.linalg.norm(draws - self.mean[None], axis=-1).max(axis=-1)  # (samples, B)
        return np.quantile(worst, quantile, axis=0)

    def take(self, index) -> "EffectDistribution":
        """The predictions `index` (an int array or a slice over B)."""
        return EffectDistribution(self.means[:, index], self.variances[:, index])


class EffectEnsemble:
    """M effect models (bootstrap members with spread heads) behind the single model's planner API."""

    def __init__(self, members: Sequence[EffectModel], info: dict[str, Any] | None = None) -> None:
        if not members:
            raise ValueError("an ensemble needs at least one member")
        configs = {tuple(sorted(m.config.to_dict().items())) for m in members}
        if len(configs) > 1:
            raise ValueError("the members of an ensemble must share one network configuration")
        self.members = [m.eval() for m in members]
        self.info = dict(info or {})

    @property
    def config(self) -> ModelConfig:
        return self.members[0].config

    def __len__(self) -> int:
        return len(self.members)

    def distribution(self, Xs: np.ndarray, actions) -> EffectDistribution:
        """Each member's displacement and variance (M, B, n, 3) for B scenes Xs (B, n, 5), one action each."""
        parts = [m.predict_gaussian(Xs, actions) for m in self.members]
        return EffectDistribution(np.stack([p[0] for p in parts]), np.stack([p[1] for p in parts]))

    def predict_effects(self, Xs: np.ndarray, actions) -> np.ndarray:
        """(B, n, 3) the members' mean displacement, metres, for B scenes, one action each."""
        return np.mean([m.predict_effects(Xs, actions) for m in self.members], axis=0)

    def predict_effect(self, X: np.ndarray, actions) -> np.ndarray:
        """(B, n, 3) the members' mean displacement, metres, for B actions on one scene X (n, 5)."""
        return np.mean([m.predict_effect(X, actions) for m in self.members], axis=0)


def distribution_of(model, Xs: np.ndarray, actions) -> EffectDistribution:
    """The predicted distribution of any Dynamics Model: an ensemble's members, a single model's mean and spread
    head (one member), or a model with `predict_effects` alone (one member, no spread)."""
    if hasattr(model, "distribution"):
        return model.distribution(Xs, actions)
    if hasattr(model, "predict_gaussian"):
        mean, variance = model.predict_gaussian(Xs, actions)
        return EffectDistribution(mean[None], variance[None])
    Xs = np.asarray(Xs, dtype=float)
    a = as_action_array(actions)
    if hasattr(model, "predict_effects"):
        mean = model.predict_effects(Xs, a)
    else:
        mean = np.stack([model.predict_effect(X, a[b:b + 1])[0] for b, X in enumerate(Xs)]) if len(a) else \
            np.zeros((0, *Xs.shape[1:2], 3))
    return EffectDistribution(mean[None], np.zeros_like(mean)[None])


def save_ensemble(path: str | Path, members: Sequence[EffectModel], info: dict[str, Any] | None = None) -> None:
    """Atomically write an ensemble file (see the module docstring)."""
    payload = {"format": ENSEMBLE_FORMAT, "info": dict(info or {}),
               "members": [{"config": m.config.to_dict(),
                            "state_dict": {k: v.detach().clone() for k, v in m.state_dict().items()}}
                           for m in members]}
    buf = io.BytesIO()
    torch.save(payload, buf)
    atomic_write_bytes(Path(path), lambda f: f.write(buf.getbuffer()))


def read_ensemble(payload: dict[str, Any], path: str | Path) -> EffectEnsemble:
    """An EffectEnsemble from a loaded ensemble payload; ValueError naming `path` if it is not one."""
    members = payload.get("members")
    if not isinstance(members, list) or not members:
        raise ValueError(f"{path}: an ensemble file without members")
    models = [model_from_payload({"format": CKPT_FORMAT, **m}, f"{path} member {k}") for k, m in enumerate(members)]
    try:
        return EffectEnsemble(models, payload.get("info"))
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


def load_dynamics(path: str | Path) -> "EffectModel | EffectEnsemble":
    """The Dynamics Model stored at `path`: a single effect model or an ensemble (eval mode, CPU)."""
    payload = read_checkpoint(path, formats=(CKPT_FORMAT, ENSEMBLE_FORMAT))
    if payload["format"] == ENSEMBLE_FORMAT:
        return read_ensemble(payload, path)
    return model_from_payload(payload, path)


def member_models(path: str | Path) -> list[EffectModel]:
    """The networks stored at `path`: an ensemble's members, or the one model of a single checkpoint."""
    model = load_dynamics(path)
    return list(model.members) if isinstance(model, EffectEnsemble) else [model]
