"""Training of the effect model: masked MSE of the paper's Eq. 1, Adam, best-by-validation.

Loss per sample = sum over real objects of ||e_hat_i - e_i||^2 (Eq. 1), in units of the
model's ``effect_scale`` (a single scalar, so the geometry of Eq. 1 is kept), averaged over the
batch. Reported "effect error" is the mean over real objects of ||e_hat_i - e_i||_2 in cm; it
is the same for the arm-subtracted target and for absolute displacements (the arm term is
known exactly). The zero-effect baseline (predict X' = X) is reported next to it.

Files: ``out_path`` holds the best model by validation error; ``<out>.last.pt`` holds the
latest epoch with optimizer and RNG state, which ``resume=True`` continues from exactly.

Speed. The paper's settings (batch 128, lr 1e-4, float32) spend nearly all their time
in matrix products that already run near one core's float32 peak, so the levers are fewer
cheaper flops and fewer steps: ``precision="bfloat16"`` runs the forward and backward passes under
bfloat16 autocast (weights, Adam state, loss and validation stay float32), about 3x the samples/s
on a CPU with AVX512-BF16 or AMX (slower elsewhere: `bf16_fast`); larger batches
(`TrainConfig.fast()`, batch 1024) feed bigger matrix products, with the learning rate scaled
linearly from the paper's 1e-4 at batch 128 (`scaled_lr`: 8e-4 at 1024). On the quick-scale data
the linear scaling kept the error per epoch of batch 128 (so the time to an error falls with the
samples/s), while square-root scaling (2.8e-4) needed ~2.5x the epochs and the unscaled 1e-4 more
still; figures in learned/README.md (training). The epoch's permutation is applied once
(contiguous slices per step), and running statistics stay tensors until the epoch ends.

Stopping. ``epochs`` is a maximum; with ``patience_epochs`` training stops once the validation
error has not improved by ``min_delta_cm`` for that many epochs ("converged"). Why a run stopped
is a `StopReason`, kept in the result, in both checkpoints and on the last history record. Only
``time_limit_s`` depends on the machine: such a run is ``finished == False`` and resuming it gives
what one uninterrupted run would have; resuming a finished run returns its result without training.
"""
from __future__ import annotations

import copy
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
from tqdm.auto import tqdm

from .checkpoint import model_from_payload, read_checkpoint, save_checkpoint, update_train_state
from .dataset import Transitions, load_transitions
from .effects import arm_displacement, effect_targets, moved_picks
from .model import EffectModel, ModelConfig, with_whole_action

Precision = Literal["float32", "bfloat16"]
PAPER_BATCH, PAPER_LR = 128, 1e-4
"""The paper's (and the bundled models') Adam batch size and learning rate."""


class StopReason(str, Enum):
    """Why training stopped. All but TIME_LIMIT are properties of the data and settings alone."""
    CONVERGED = "converged"            # no validation improvement for patience_epochs
    MAX_EPOCHS = "max_epochs"          # ``epochs`` reached
    TARGET_REACHED = "target_reached"  # validation error <= target_val_cm
    MAX_STEPS = "max_steps"            # ``max_steps`` optimizer steps taken
    TIME_LIMIT = "time_limit"          # wall-clock cap: unfinished, resume to finish


def scaled_lr(batch_size: int, base_lr: float = PAPER_LR, base_batch: int = PAPER_BATCH) -> float:
    """Adam learning rate for ``batch_size``: ``base_lr * batch_size / base_batch`` (linear scaling).

    Measured on the quick-scale data at batch 1024: linear (8e-4) matched batch 128's validation
    error per epoch; square root (2.8e-4) and none (1e-4) fell behind (learned/README.md).
    """
    return base_lr * batch_size / base_batch


def bf16_fast() -> bool:
    """Whether this CPU multiplies bfloat16 natively (AVX512-BF16 or AMX), so autocast pays."""
    try:
        flags = Path("/proc/cpuinfo").read_text()
    except OSError:
        return False
    return torch.backends.mkldnn.is_available() and any(f in flags for f in (" avx512_bf16", " amx_bf16"))


@dataclass(frozen=True)
class TrainConfig:
    """How to train (the architecture is `ModelConfig`'s). The defaults are the paper's settings, those
    of the bundled models: Adam at batch 128 and lr 1e-4 in float32 for a fixed number of epochs.
    `TrainConfig.fast()` gives faster ones: batch 1024 with the learning rate scaled linearly,
    bfloat16 autocast where the CPU has it natively, one thread, early stopping."""

    epochs: int = 100  # at most
    batch_size: int = PAPER_BATCH
    lr: float = PAPER_LR
    precision: Precision = "float32"
    threads: int | None = None  # torch threads (None: leave torch's setting)
    patience_epochs: int | None = None  # stop after this many epochs without improvement (None: never)
    min_delta_cm: float = 0.0  # the least decrease of the validation error that counts as improvement
    val_fraction: float = 0.1  # the seeded validation split, when no val_data is given
    seed: int = 0
    only_moved: bool = False  # only the transitions that moved their picked block (the Symbolic Model)
    max_steps: int | None = None  # optimizer steps at most
    target_val_cm: float | None = None  # stop once the validation error reaches this
    time_limit_s: float | None = None  # wall-clock cap of one call: the run is then unfinished, resumable
    # weight of a penalty on each learned bit (unary, and relation over pairs i != j) whose batch rate
    # leaves [USAGE_LOW, 1 - USAGE_LOW]: a head the effect loss could leave constant stays in use (0: off)
    bit_usage: float = 0.0
    # weight of the offset loss (`ModelConfig.offset_decoder`, `offset_loss`): each pair's squashed offset
    # read back from its bits, so that relations say where blocks stand; 0: off (the paper's objective)
    offset_weight: float = 0.0
    # the offset loss reads back only pairs whose centres lie within this distance on the table (metres;
    # farther pairs read as "no offset"), so relations say where a neighbour stands and a block moved far
    # from a bystander leaves their relations as they were; None: every pair (the side of every block)
    offset_radius_m: float | None = None
    # weight of the position loss (`ModelConfig.position_decoder`, `position_loss`): each block's place on
    # the table read back from its unary bits, so that a unary bit says where a block stands; 0: off
    position_weight: float = 0.0
    # weight of the transition loss (`ModelConfig.transition_decoder`, `transition_loss`): the bits read after
    # each step predicted from the bits before it and the action, so that operators predict their steps; 0: off
    transition_weight: float = 0.0

    def __post_init__(self) -> None:
        if self.precision not in ("float32", "bfloat16"):
            raise ValueError(f"precision must be float32 or bfloat16, got {self.precision!r}")
        if self.patience_epochs is not None and self.patience_epochs < 1:
            raise ValueError(f"patience_epochs must be >= 1, got {self.patience_epochs}")
        if self.epochs < 1 or self.batch_size < 1 or not self.lr > 0:
            raise ValueError(f"epochs and batch_size must be >= 1 and lr > 0, got {self.epochs}, "
                             f"{self.batch_size}, {self.lr}")
        if not 0.0 < self.val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in (0, 1), got {self.val_fraction}")
        if not self.bit_usage >= 0.0:
            raise ValueError(f"bit_usage must be >= 0, got {self.bit_usage}")
        if not self.offset_weight >= 0.0:
            raise ValueError(f"offset_weight must be >= 0, got {self.offset_weight}")
        if not self.position_weight >= 0.0:
            raise ValueError(f"position_weight must be >= 0, got {self.position_weight}")
        if not self.transition_weight >= 0.0:
            raise ValueError(f"transition_weight must be >= 0, got {self.transition_weight}")
        if self.offset_radius_m is not None and not self.offset_radius_m > 0.0:
            raise ValueError(f"offset_radius_m must be > 0, got {self.offset_radius_m}")

    @classmethod
    def fast(cls, batch_size: int = 1024, **changes: Any) -> "TrainConfig":
        """The fast settings (learned/README.md): `lr` scaled linearly with the batch unless given,
        bfloat16 where `bf16_fast()`, one thread, patience 100 epochs, at most 1000 epochs."""
        settings: dict[str, Any] = {"epochs": 1000, "batch_size": batch_size, "lr": scaled_lr(batch_size),
                                    "precision": "bfloat16" if bf16_fast() else "float32", "threads": 1,
                                    "patience_epochs": 100}
        settings.update(changes)
        return cls(**settings)


@dataclass
class TrainResult:
    model: EffectModel            # best model by validation error, eval mode
    best_val_cm: float            # its mean effect error on the validation split, cm
    best_epoch: int
    steps: int                    # optimizer steps taken in total (including resumed ones)
    samples_per_s: float          # training throughput of this call (forward + backward)
    history: list[dict[str, Any]] = field(default_factory=list)
    out_path: Path | None = None
    stop_reason: StopReason = StopReason.MAX_EPOCHS
    epochs_reached: int = 0       # epochs trained in total (including resumed ones)

    @property
    def finished(self) -> bool:
        """False when a wall-clock cap stopped the run: resume it for the result."""
        return self.stop_reason is not StopReason.TIME_LIMIT


def train_options(train: TrainConfig, num_train: int, num_val: int, init: str | Path | None = None
                  ) -> dict[str, Any]:
    """The settings of `train` that change a run's result, as its checkpoints record them: a run resumes
    only under the same ones. The defaults are left out, so that older runs stay resumable."""
    return {**({"init": str(init)} if init is not None else {}),
            "batch_size": train.batch_size, "lr": train.lr, "val_fraction": train.val_fraction,
            "seed": train.seed, "num_train": num_train, "num_val": num_val,
            **({"only_moved": True} if train.only_moved else {}),
            **({"bit_usage": train.bit_usage} if train.bit_usage else {}),
            **({"offset_weight": train.offset_weight} if train.offset_weight else {}),
            **({"offset_radius_m": train.offset_radius_m} if train.offset_radius_m is not None else {}),
            **({"position_weight": train.position_weight} if train.position_weight else {}),
            **({"transition_weight": train.transition_weight} if train.transition_weight else {}),
            **({"precision": train.precision} if train.precision != "float32" else {}),
            **({"patience_epochs": train.patience_epochs, "min_delta_cm": train.min_delta_cm}
               if train.patience_epochs is not None else {})}


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


def last_path(out_path: str | Path) -> Path:
    """Where the resumable latest-epoch checkpoint of ``out_path`` lives."""
    p = Path(out_path)
    return p.with_name(p.stem + ".last" + (p.suffix or ".pt"))


def split_indices(num: int, fractions: tuple[float, ...], seed: int) -> list[np.ndarray]:
    """Random disjoint index sets of the given fractions; the remainder is returned first."""
    perm = np.random.default_rng(seed).permutation(num)
    sizes = [int(round(f * num)) for f in fractions]
    if sum(sizes) >= num:
        raise ValueError(f"split {fractions} leaves no training data out of {num} samples")
    parts, start = [], num - sum(sizes)
    for s in sizes:
        parts.append(np.sort(perm[start:start + s]))
        start += s
    return [np.sort(perm[:num - sum(sizes)]), *parts]


def prepare(data: Transitions) -> dict[str, torch.Tensor]:
    """Tensors for training: inputs, padding mask and arm-subtracted effect targets (metres)."""
    t = data.tensors()
    X, Xn, M, A = t["X"].float(), t["X_next"].float(), t["mask"], t["action"].long()
    return {"X": X, "mask": M, "action": A, "target": effect_targets(X, Xn, A, M),
            "absolute": (Xn[..., :3] - X[..., :3]) * M[..., None], "X_next": Xn}


def normalisation(t: dict[str, torch.Tensor]) -> dict[str, Any]:
    """Position mean/std, effect scale and arm-motion scale (metres) from training tensors."""
    M = t["mask"]
    pos = t["X"][..., :3][M]
    target = t["target"][M]
    arm = arm_displacement(t["X"], t["action"])
    return {"pos_mean": pos.mean(0), "pos_std": pos.std(0).clamp_min(0.01),
            "effect_scale": float(target.pow(2).mean().sqrt().clamp_min(0.001)),
            "arm_scale": float(arm.pow(2).sum(-1).mean().sqrt().clamp_min(0.01))}


@torch.no_grad()
def evaluate(model: EffectModel, data: "Transitions | dict[str, torch.Tensor]",
             batch_size: int = 4096) -> dict[str, float]:
    """Mean effect error (cm) over real objects, with two baselines, and the Eq. 1 loss.

    Baselines: ``zero_cm`` predicts no motion (X' = X); ``arm_cm`` predicts a zero target, i.e.
    the pick object follows the gripper exactly and nothing else moves.
    """
    t = prepare(data) if isinstance(data, Transitions) else data
    was_training = model.training
    model.eval()
    err = zero = arm = sq = 0.0
    count = 0
    N = t["X"].shape[0]
    for s in range(0, N, batch_size):
        sl = slice(s, s + batch_size)
        M = t["mask"][sl]
        d = model(t["X"][sl], t["action"][sl], M) - t["target"][sl]
        err += d.norm(dim=-1)[M].sum().item()
        zero += t["absolute"][sl].norm(dim=-1)[M].sum().item()
        arm += t["target"][sl].norm(dim=-1)[M].sum().item()
        sq += d.pow(2).sum().item()
        count += int(M.sum())
    model.train(was_training)
    return {"err_cm": 100 * err / count, "zero_cm": 100 * zero / count,
            "arm_cm": 100 * arm / count,
            "loss": sq / N / float(model.effect_scale) ** 2}


class _Plateau:
    """Early-stopping bookkeeping: the epoch of the last improvement by more than ``min_delta_cm``
    over the error at the previous such improvement (rebuilt from the history on resume)."""

    def __init__(self, min_delta_cm: float, history: list[dict[str, Any]]) -> None:
        self.min_delta_cm, self.ref_cm, self.epoch = min_delta_cm, math.inf, -1
        for h in history:
            self.update(h["epoch"], h["val_err_cm"])

    def update(self, epoch: int, val_cm: float) -> None:
        if val_cm < self.ref_cm - self.min_delta_cm:
            self.ref_cm, self.epoch = val_cm, epoch


def train_model(data: "str | Path | Sequence[str | Path] | Transitions", config: ModelConfig | None = None,
                train: TrainConfig | None = None, out_path: str | Path | None = None, *,
                val_data: Transitions | None = None, resume: bool = False, progress: bool = True,
                init: str | Path | None = None) -> TrainResult:
    """Train an EffectModel on a dataset directory (or several: `load_transitions`) or in-memory Transitions.

    Validation data is ``val_data`` if given, else a seeded ``val_fraction`` split of ``data``.
    Validates after every epoch (and when ``max_steps`` stops training early), keeps the best
    model by validation effect error (written to ``out_path`` if given) and the latest state
    (``last_path(out_path)``). ``resume=True`` continues from the latest state up to ``epochs``.
    Training stops (`StopReason`) after at most ``epochs`` epochs / ``max_steps`` steps, once the
    validation error has not improved by ``min_delta_cm`` for ``patience_epochs`` epochs, once it
    reaches ``target_val_cm``, or (unfinished) before an epoch that would start after
    ``time_limit_s`` of this call's wall time (each call trains at least one epoch); history
    records carry ``elapsed_s``.
    ``only_moved`` keeps the transitions that moved their picked block (`effects.moved_picks`),
    in training and validation alike: what the Symbolic Model learns its symbols from.
    `train` (default `TrainConfig()`, the paper's settings) says how; the names above are its fields.
    ``init`` (a checkpoint) fine-tunes: training starts from its weights and input normalisation instead
    of random ones, with its network settings (``config``, if given, must agree) and the data's object
    limit, e.g. the bundled 2-4 block models on data that adds 5 and 6 blocks.
    """
    train = train or TrainConfig()
    if train.threads:
        torch.set_num_threads(train.threads)
    if not isinstance(data, Transitions):
        data = load_transitions(data)
    if train.only_moved:
        data = data.subset(np.flatnonzero(moved_picks(data.X, data.X_next, data.action)))
        if val_data is not None:
            val_data = val_data.subset(np.flatnonzero(moved_picks(val_data.X, val_data.X_next, val_data.action)))
        if len(data) == 0:
            raise ValueError("no transition moved its picked block: nothing to train on with only_moved")
    if val_data is None:
        train_idx, val_idx = split_indices(len(data), (train.val_fraction,), train.seed)
        data, val_data = data.subset(train_idx), data.subset(val_idx)
    if len(val_data) == 0:
        raise ValueError("empty validation split")
    initial = None if init is None else model_from_payload(read_checkpoint(init), init)
    if initial is not None:
        own = {**initial.config.to_dict(), "n_max": data.n_max}
        if config is not None and config.spread:  # a spread head may be added to a network without one
            own["spread"] = True
        if config is not None and config.whole_action:  # and the whole action to the paper's encoding
            own["whole_action"] = True
        given = own if config is None else {**config.to_dict(), "n_max": data.n_max}
        if given != own:
            differ = ", ".join(f"{k} {given[k]!r} (its {own[k]!r})" for k in own if given[k] != own[k])
            raise ValueError(f"{init}: the network to fine-tune has other settings than asked for: {differ}")
        config = ModelConfig.from_dict(own)
    config = config or ModelConfig(n_max=data.n_max)
    if data.n_max > config.n_max:
        raise ValueError(f"dataset n_max {data.n_max} exceeds model n_max {config.n_max}")
    if train.offset_weight and not config.offset_decoder:
        raise ValueError("offset_weight needs a model with offset_decoder=True (the head it trains)")
    if train.position_weight and not config.position_decoder:
        raise ValueError("position_weight needs a model with position_decoder=True (the head it trains)")
    if train.transition_weight and not config.transition_decoder:
        raise ValueError("transition_weight needs a model with transition_decoder=True (the head it trains)")
    options = train_options(train, len(data), len(val_data), init)
    tr, va = prepare(data), prepare(val_data)

    torch.manual_seed(train.seed)
    model = EffectModel(config)
    stats = normalisation(tr)
    model.set_normalisation(**stats)
    if initial is not None:  # its weights and normalisation buffers (a spread head it lacks starts anew)
        state = initial.state_dict()
        if config.whole_action and not initial.config.whole_action:
            state = with_whole_action(state, config)
        missing, unexpected = model.load_state_dict(state, strict=False)
        if unexpected or any(not k.startswith("spread_head.") for k in missing):
            raise ValueError(f"{init}: its weights do not fit the network ({missing + unexpected})")
    opt = torch.optim.Adam(model.parameters(), lr=train.lr)
    epoch0, step, history = 0, 0, []
    best: dict[str, Any] = {"val_cm": float("inf"), "epoch": -1, "state": None}

    if resume:
        if out_path is None:
            raise ValueError("resume=True needs out_path")
        lp = last_path(out_path)
        if lp.exists():
            payload = read_checkpoint(lp)
            st = payload.get("train")
            if not st:
                raise ValueError(f"{lp}: no training state to resume from")
            # configs compared as dataclasses: a field added since the run began takes its default
            if ModelConfig.from_dict(payload["config"]) != config or st["options"] != options:
                raise ValueError(f"{lp}: was trained with a different config/options/data; "
                                 f"refusing to resume ({payload['config']}, {st['options']})")
            model = model_from_payload(payload, lp).train()
            opt = torch.optim.Adam(model.parameters(), lr=train.lr)
            opt.load_state_dict(st["optimizer"])
            epoch0, step = int(st["epoch"]) + 1, int(st["step"])
            history = [{k: v for k, v in h.items() if k != "stop_reason"} for h in st["history"]]
            torch.set_rng_state(st["rng"])
            best_payload = read_checkpoint(out_path)
            best = {"val_cm": float(st["best_val_cm"]), "epoch": int(st["best_epoch"]),
                    "state": best_payload["state_dict"]}
    model.train()

    N = len(data)
    steps_per_epoch = (N + train.batch_size - 1) // train.batch_size
    total = train.epochs * steps_per_epoch
    if train.max_steps is not None:
        total = min(train.max_steps, total)
    bar = tqdm(total=total, initial=min(step, total), disable=not progress, unit="step",
               dynamic_ncols=True)
    scale = float(model.effect_scale)
    plateau = _Plateau(train.min_delta_cm, history)
    train_time, trained = 0.0, 0
    start = time.perf_counter()
    elapsed0 = history[-1]["elapsed_s"] if history else 0.0
    epoch = epoch0

    def stop_reason() -> StopReason | None:
        """Why not to train epoch ``epoch``. The wall-clock cap comes last, so that it never hides another
        reason, and lets every call train an epoch, so that resuming time-limited calls always progresses."""
        patience = train.patience_epochs
        if patience is not None and plateau.epoch >= 0 and epoch - 1 - plateau.epoch >= patience:
            return StopReason.CONVERGED
        if train.target_val_cm is not None and best["val_cm"] <= train.target_val_cm:
            return StopReason.TARGET_REACHED
        if train.max_steps is not None and step >= train.max_steps:
            return StopReason.MAX_STEPS
        if epoch >= train.epochs:
            return StopReason.MAX_EPOCHS
        if train.time_limit_s is not None and epoch > epoch0 and time.perf_counter() - start > train.time_limit_s:
            return StopReason.TIME_LIMIT
        return None

    while (reason := stop_reason()) is None:
        perm = torch.randperm(N, generator=torch.Generator().manual_seed(train.seed * 100003 + epoch))
        # One gather per epoch; the steps then slice contiguous views.
        Xe, Ae, Me, Te = (tr[k][perm] for k in ("X", "action", "mask", "target"))
        Ne = tr["X_next"][perm] if train.transition_weight else None
        run_loss, run_err = torch.zeros((), dtype=torch.float64), torch.zeros((), dtype=torch.float64)
        run_b = 0
        t0 = time.perf_counter()
        for s in range(0, N, train.batch_size):
            batch = slice(s, s + train.batch_size)
            X, A, M, T = Xe[batch], Ae[batch], Me[batch], Te[batch]
            with torch.autocast("cpu", dtype=torch.bfloat16, enabled=train.precision == "bfloat16"):
                u, r, unary, relation = model.encode_logits(X, M)
                pred = model.decode(X, A, M, u, r)
                usage = bit_usage_penalty(unary, relation, M) if train.bit_usage else None
                offsets = offset_loss(model, X, M, u, r, train.offset_radius_m) if train.offset_weight else None
                places = position_loss(model, X, M, u) if train.position_weight else None
                steps = None if Ne is None else transition_loss(model, X, Ne[batch], A, M, u, r)
            d = pred.float() - T
            loss = (d / scale).pow(2).sum(dim=(1, 2)).mean()
            if usage is not None:
                loss = loss + train.bit_usage * usage
            if offsets is not None:
                loss = loss + train.offset_weight * offsets
            if places is not None:
                loss = loss + train.position_weight * places
            if steps is not None:
                loss = loss + train.transition_weight * steps
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            step += 1
            n = X.shape[0]
            trained += n
            with torch.no_grad():  # running sums stay tensors: read once per epoch
                run_loss += loss.detach() * n
                run_err += d.detach().norm(dim=-1).mul(M).sum()
            run_b += n
            bar.update(1)
            if train.max_steps is not None and step >= train.max_steps:
                break
        train_time += time.perf_counter() - t0
        run_n = int(Me[:run_b].sum())  # real objects trained on this epoch
        val = evaluate(model, va)
        rec = {"epoch": epoch, "step": step, "train_err_cm": 100 * float(run_err) / max(run_n, 1),
               "val_err_cm": val["err_cm"], "val_zero_cm": val["zero_cm"], "val_loss": val["loss"],
               "elapsed_s": elapsed0 + time.perf_counter() - start}
        history.append(rec)
        plateau.update(epoch, val["err_cm"])
        if val["err_cm"] < best["val_cm"]:
            best = {"val_cm": val["err_cm"], "epoch": epoch,
                    "state": copy.deepcopy(model.state_dict())}
            if out_path is not None:
                save_checkpoint(out_path, model, {"kind": "best", "epoch": epoch, "step": step,
                                                  "val_err_cm": val["err_cm"], "options": options})
        if out_path is not None:
            save_checkpoint(last_path(out_path), model, {
                "kind": "last", "epoch": epoch, "step": step, "options": options,
                "optimizer": opt.state_dict(), "rng": torch.get_rng_state(),
                "best_val_cm": best["val_cm"], "best_epoch": best["epoch"], "history": history})
        bar.set_postfix(epoch=epoch, loss=f"{float(run_loss) / max(run_b, 1):.4f}", val_cm=f"{val['err_cm']:.2f}",
                        best_val_cm=f"{best['val_cm']:.2f}", zero_cm=f"{val['zero_cm']:.2f}")
        epoch += 1
    bar.close()

    if best["state"] is None:
        raise ValueError("no training epoch ran (epochs already reached?)")
    epochs_reached = len(history)
    stop = {"stop_reason": reason.value, "finished": reason is not StopReason.TIME_LIMIT,
            "epochs_reached": epochs_reached}
    if history:
        history[-1]["stop_reason"] = reason.value
    if out_path is not None:
        update_train_state(out_path, stop)
        if last_path(out_path).exists():
            update_train_state(last_path(out_path), {**stop, "history": history})
    final = EffectModel(config)
    final.load_state_dict(best["state"])
    return TrainResult(model=final.eval(), best_val_cm=best["val_cm"], best_epoch=best["epoch"],
                       steps=step, samples_per_s=trained / train_time if train_time else 0.0,
                       history=history, out_path=Path(out_path) if out_path else None,
                       stop_reason=reason, epochs_reached=epochs_reached)
