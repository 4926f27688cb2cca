"""How widely the world scatters an action's outcome: fitting a model's ``spread`` head.

The mean of a trained Dynamics Model is the paper's (Eq. 1). Its ``spread`` head predicts, per object
and axis, the variance of the effect about that mean: a bar released against a cube's edge may tip
either way, and no mean gets that right. The head is fitted after the mean, with the rest of the
network frozen, by the Gaussian negative log-likelihood of the mean's residuals:

    NLL = 1/2 sum_axes (d^2 / s^2 + log s^2),   s^2 = exp(head(h)) scale^2 + floor^2

over the real objects (d: residual, h: the decoder's features and the object's action encoding,
`EffectModel.spread_input`). The features
are computed once, so a fit takes seconds; the head kept is the one with the best validation NLL.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import torch

from .dataset import Transitions
from .model import SPREAD_FLOOR_M, EffectModel

CHI2_3_95 = 7.814727903251178  # the 95 % quantile of chi-squared with 3 degrees of freedom


@dataclass(frozen=True)
class SpreadConfig:
    """How to fit the spread head (Adam on precomputed features; early stopping on validation NLL)."""
    epochs: int = 200            # at most
    patience_epochs: int = 15    # stop after this many epochs without a better validation NLL
    batch_size: int = 512        # objects per step
    lr: float = 1e-3
    seed: int = 0


@torch.no_grad()
def _features(model: EffectModel, t: dict[str, torch.Tensor], batch_size: int = 4096
              ) -> tuple[torch.Tensor, torch.Tensor]:
    """The spread head's input for every real object (M, K d_msg + action encoding) and its residual (M, 3) in
    effect-scale units."""
    feats, residuals = [], []
    for s in range(0, t["X"].shape[0], batch_size):
        X, A, M = t["X"][s:s + batch_size], t["action"][s:s + batch_size], t["mask"][s:s + batch_size]
        u, r = model.encode(X, M)
        h = model.messages(X, A, M, u, r)
        d = (model._effect(h, X, M) - t["target"][s:s + batch_size]) / model.effect_scale
        feats.append(model.spread_input(h, X, A)[M])
        residuals.append(d[M])
    return torch.cat(feats), torch.cat(residuals)


def gaussian_nll(log_var: torch.Tensor, residual: torch.Tensor, floor: float) -> torch.Tensor:
    """Mean over objects of 1/2 sum_axes (d^2 / s^2 + log s^2), s^2 = exp(log_var) + floor^2 (scale units)."""
    var = log_var.clamp(-30.0, 10.0).exp() + floor ** 2
    return 0.5 * (residual.pow(2) / var + var.log()).sum(-1).mean()


def coverage(log_var: torch.Tensor, residual: torch.Tensor, floor: float) -> float:
    """Share of objects whose residual lies inside the predicted 95 % ellipsoid (chi-squared, 3 axes)."""
    var = log_var.clamp(-30.0, 10.0).exp() + floor ** 2
    return float((residual.pow(2) / var).sum(-1).le(CHI2_3_95).float().mean())


def fit_spread(model: EffectModel, train: Transitions, val: Transitions,
               config: SpreadConfig = SpreadConfig()) -> dict[str, float]:
    """Fit `model`'s spread head (in place, the rest frozen) to the residuals of its mean on `train`, keeping
    the head of the best validation NLL; returns its figures (NLL in effect-scale units, coverage of the 95 %
    ellipsoid, epochs)."""
    from .train import prepare

    if not model.config.spread:
        raise ValueError("the model has no spread head (ModelConfig.spread)")
    model.eval()
    floor = SPREAD_FLOOR_M / float(model.effect_scale)
    h_train, d_train = _features(model, prepare(train))
    h_val, d_val = _features(model, prepare(val))
    head = model.spread_head
    torch.manual_seed(config.seed)
    opt = torch.optim.Adam(head.parameters(), lr=config.lr)
    best_nll, best_epoch, best_state = math.inf, -1, copy.deepcopy(head.state_dict())
    generator = torch.Generator().manual_seed(config.seed)
    head.train()
    for epoch in range(config.epochs):
        perm = torch.randperm(h_train.shape[0], generator=generator)
        for s in range(0, len(perm), config.batch_size):
            idx = perm[s:s + config.batch_size]
            loss = gaussian_nll(head(h_train[idx]), d_train[idx], floor)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
        with torch.no_grad():
            nll = float(gaussian_nll(head(h_val), d_val, floor))
        if nll < best_nll:
            best_nll, best_epoch, best_state = nll, epoch, copy.deepcopy(head.state_dict())
        elif epoch - best_epoch >= config.patience_epochs:
            break
    head.load_state_dict(best_state)
    head.eval()
    with torch.no_grad():
        cover = coverage(head(h_val), d_val, floor)
    return {"val_nll": best_nll, "val_coverage95": cover, "spread_best_epoch": best_epoch,
            "spread_epochs": epoch + 1, "objects": int(h_train.shape[0])}

