"""The auxiliary losses of the Symbolic Model's training (`TrainConfig`'s weights), beside Eq. 1.

- `bit_usage_penalty`: learned bits that are always 0 or always 1 in a batch (`bit_usage`);
- `position_loss`: where a block is on the table, read back from its unary bits (`position_weight`);
- `offset_loss`: where j is from i, read back from the pair's bits (`offset_weight`);
- `transition_loss`: the bits after a step, predicted from those before it and the action
  (`transition_weight`).
"""
from __future__ import annotations

import torch

from .model import EffectModel

USAGE_LOW = 0.05  # `TrainConfig.bit_usage`: a bit set in under 5 % or over 95 % of a batch is penalised
USAGE_SHARPNESS = 4.0  # the rate counts sigmoid(4 logit): close to the read bit (logit > 0), with a gradient


def bit_usage_penalty(unary: torch.Tensor, relation: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Sum over learned bits of how far each one's rate in the batch lies outside [USAGE_LOW, 1 -
    USAGE_LOW], in units of USAGE_LOW: 0 for bits in use, 1 for a bit that is always 0 or always 1.
    The rate is that of the bits as read (logit > 0), made differentiable (`USAGE_SHARPNESS`), not of
    the Gumbel samples, whose noise sets a bit now and then whatever its logit. unary (B, N, d_z) and
    relation (B, K, N, N) are the learned logits (`EffectModel.encode_logits`), mask (B, N) the real
    objects; the diagonal r_k(i, i) is left out."""
    m = mask.float()
    u = torch.sigmoid(USAGE_SHARPNESS * unary.float())
    rates = [(u * m[..., None]).sum(dim=(0, 1)) / m.sum()]
    N = mask.shape[1]
    pairs = (m[:, :, None] * m[:, None, :]) * (1 - torch.eye(N, dtype=m.dtype))
    if float(pairs.sum()) > 0:
        r = torch.sigmoid(USAGE_SHARPNESS * relation.float())
        rates.append((r * pairs[:, None]).sum(dim=(0, 2, 3)) / pairs.sum())
    rate = torch.cat(rates)
    return (torch.relu(USAGE_LOW - rate) + torch.relu(rate - 1 + USAGE_LOW)).sum() / USAGE_LOW


def position_loss(model: EffectModel, X: torch.Tensor, mask: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """Mean over real objects of the squared error (summed over x, y) of the squashed place on the table
    read back from the object's unary bits (`EffectModel.reconstruct_positions`)."""
    err = (model.reconstruct_positions(u).float() - model.squashed_positions(X.float())).pow(2).sum(dim=-1)
    real = mask.float()
    return (err * real).sum() / real.sum().clamp(min=1.0)


def offset_loss(model: EffectModel, X: torch.Tensor, mask: torch.Tensor, u: torch.Tensor,
                r: torch.Tensor, radius_m: float | None = None) -> torch.Tensor:
    """Mean over real pairs i != j of the squared error (summed over x, y, z) of the squashed offset
    tanh((x_j - x_i) / 5 cm) read back from the pair's bits (`EffectModel.reconstruct_offsets`); with
    `radius_m`, pairs farther apart than that on the table are to read as 0."""
    N = mask.shape[1]
    pairs = (mask[:, :, None] & mask[:, None, :] & ~torch.eye(N, dtype=torch.bool, device=mask.device)).float()
    target = model.squashed_offsets(X.float())
    if radius_m is not None:
        near = model.pair_offsets(X.float())[..., :2].norm(dim=-1) < radius_m
        target = target * near[..., None]
    err = (model.reconstruct_offsets(u, r).float() - target).pow(2).sum(dim=-1)
    return (err * pairs).sum() / pairs.sum().clamp(min=1.0)


def transition_loss(model: EffectModel, X: torch.Tensor, X_next: torch.Tensor, action: torch.Tensor,
                    mask: torch.Tensor, u: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
    """Mean binary cross-entropy, over the learned bits of real objects and pairs i != j, of the bits
    read on X_next (their sigmoids, not samples) predicted from the bits u, r before the step and the
    action (`EffectModel.predict_next_logits`). The gradient reaches the bits after the step too: the
    encoder is asked for bits a step's outcome can be predicted in, beside the effect they must explain."""
    d_z = model.config.d_z
    next_unary, next_relation = model.unary_logits(X_next), model.relation_logits(X_next)
    pred_unary, pred_relation = model.predict_next_logits(X, action, u, r)
    bce = torch.nn.functional.binary_cross_entropy_with_logits
    m = mask.float()
    unary = bce(pred_unary.float(), torch.sigmoid(next_unary.float()), reduction="none").sum(-1)
    N = mask.shape[1]
    pairs = (m[:, :, None] * m[:, None, :]) * (1 - torch.eye(N, dtype=m.dtype, device=m.device))
    relation = bce(pred_relation.float(), torch.sigmoid(next_relation.float()), reduction="none").sum(1)
    return (unary * m).sum() / (m.sum() * d_z).clamp(min=1.0) + \
        (relation * pairs).sum() / (pairs.sum() * next_relation.shape[1]).clamp(min=1.0)


__all__ = ["USAGE_LOW", "USAGE_SHARPNESS", "bit_usage_penalty", "offset_loss", "position_loss", "transition_loss"]
