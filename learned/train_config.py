"""How to train an effect model (`TrainConfig`), why a training stopped (`StopReason`) and what it gives
(`TrainResult`); `learned.train` trains by them."""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any, Literal, get_args

import torch

from .model import EffectModel

Precision = Literal["float32", "bfloat16"]
EffectLoss = Literal["squared", "distance"]
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
    # the effect loss per object: "squared" distance (the paper's Eq. 1: the mean of the outcomes) or the
    #   "distance" itself (a median: where one outcome is the more frequent, near it, not between two outcomes)
    effect_loss: EffectLoss = "squared"

    def __post_init__(self) -> None:
        for name, allowed in (("precision", get_args(Precision)), ("effect_loss", get_args(EffectLoss))):
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name} must be {' or '.join(allowed)}, got {getattr(self, name)!r}")
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
            **({"effect_loss": train.effect_loss} if train.effect_loss != "squared" else {}),
            **({"patience_epochs": train.patience_epochs, "min_delta_cm": train.min_delta_cm}
               if train.patience_epochs is not None else {})}


__all__ = ["PAPER_BATCH", "PAPER_LR", "EffectLoss", "Precision", "StopReason", "TrainConfig", "TrainResult",
           "bf16_fast", "scaled_lr", "train_options"]
